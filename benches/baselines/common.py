"""Shared pieces of the baselines: reading MCAP logs through ``hbn.read_mcap``, building the
HBN's two training sets, and the scores (the same definitions as ``hbn eval`` /
``hbn.Estimate.score``, reimplemented in numpy so that a method without a standard deviation,
the LSTM, is scored by the same code).

Nothing here keeps state between calls.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

#: Default Foxglove message paths of u, x and y, as written by ``hbn simulate``.
DEFAULT_PATHS: Dict[str, str] = {"u": "/input.data", "x": "/state.data", "y": "/sensor.data"}


@dataclass(frozen=True)
class Log:
    """One logged trajectory on a uniform grid: input ``u``, state ``x``, sensor output ``y``."""

    u: np.ndarray
    x: np.ndarray
    y: np.ndarray
    rate: float
    path: str = ""

    def __len__(self) -> int:
        return int(self.u.shape[0])


def native_rate(t: np.ndarray) -> float:
    """Sample rate (Hz) of a time column: ``1 / median(diff(t))``, rounded to 1e-6 Hz."""
    t = np.asarray(t, dtype=np.float64)
    if t.shape[0] < 2:
        raise ValueError("a log needs at least two samples to have a rate")
    dt = float(np.median(np.diff(t)))
    if not (dt > 0.0 and math.isfinite(dt)):
        raise ValueError(f"non-increasing time column (median step {dt})")
    return round(1.0 / dt, 6)


def read_log(path: str, paths: Mapping[str, str], rate: Optional[float] = None) -> Log:
    """Reads ``u``, ``x`` and ``y`` of one MCAP log with :func:`hbn.read_mcap`.

    ``paths`` maps ``"u"``, ``"x"``, ``"y"`` to Foxglove message paths. ``rate`` (Hz): the grid
    to resample on; ``None`` uses the log's native rate (that of ``u``).
    """
    import hbn  # imported here so the metrics can be used without the wheel

    d = hbn.read_mcap(path, {k: paths[k] for k in ("u", "x", "y")}, rate_hz=rate)
    r = native_rate(d["t"]) if rate is None else float(rate)
    return Log(u=d["u"], x=d["x"], y=d["y"], rate=r, path=str(path))


def read_logs(
    train_paths: Sequence[str], test_path: str, paths: Mapping[str, str]
) -> Tuple[List[Log], Log]:
    """Reads the training logs and the test log on ONE grid: the native rate of the first
    training log (the rate hbn is trained with and must estimate at)."""
    if len(train_paths) == 0:
        raise ValueError("at least one training log is needed")
    first = read_log(train_paths[0], paths)
    train = [first] + [read_log(p, paths, rate=first.rate) for p in train_paths[1:]]
    test = read_log(test_path, paths, rate=first.rate)
    return train, test


def transition_rows(logs: Sequence[Log]) -> Tuple[np.ndarray, np.ndarray]:
    """The transition training set D_D: inputs ``[x_{k-1}, x_{k-2}, u_{k-1}, u_{k-2}]``, target
    ``x_k``, for ``k >= 2`` of every log (no row straddles two logs)."""
    X, t = [], []
    for lg in logs:
        if len(lg) < 3:
            continue
        X.append(np.column_stack([lg.x[1:-1], lg.x[:-2], lg.u[1:-1], lg.u[:-2]]))
        t.append(lg.x[2:])
    if not X:
        raise ValueError("no log has the 3 samples a transition row needs")
    return np.vstack(X), np.concatenate(t)


def sensor_rows(logs: Sequence[Log]) -> Tuple[np.ndarray, np.ndarray]:
    """The sensor training set D_S: inputs ``[x_{k-1}, y_{k-1}, x_k]``, target ``y_k``, for
    ``k >= 2`` of every log (as the transition set; no row straddles two logs)."""
    X, t = [], []
    for lg in logs:
        if len(lg) < 3:
            continue
        X.append(np.column_stack([lg.x[1:-1], lg.y[1:-1], lg.x[2:]]))
        t.append(lg.y[2:])
    if not X:
        raise ValueError("no log has the 3 samples a sensor row needs")
    return np.vstack(X), np.concatenate(t)


def subsample(
    X: np.ndarray, t: np.ndarray, n: int, rng: np.random.Generator
) -> Tuple[np.ndarray, np.ndarray]:
    """``n`` rows drawn without replacement (all rows, in order, if there are at most ``n``).
    Rows with a non-finite value are dropped first."""
    ok = np.all(np.isfinite(X), axis=1) & np.isfinite(t)
    X, t = X[ok], t[ok]
    if X.shape[0] <= n:
        return X, t
    idx = np.sort(rng.choice(X.shape[0], size=n, replace=False))
    return X[idx], t[idx]


# ------------------------------------------------------------------------------------------------
# Scores
# ------------------------------------------------------------------------------------------------


def rmse(x_hat: np.ndarray, x_ref: np.ndarray) -> float:
    """Root-mean-squared error over the samples where both values are finite (NaN if none)."""
    e, r = np.asarray(x_hat, dtype=np.float64), np.asarray(x_ref, dtype=np.float64)
    ok = np.isfinite(e) & np.isfinite(r)
    if not ok.any():
        return math.nan
    return float(np.sqrt(np.mean((e[ok] - r[ok]) ** 2)))


def nrmse(x_hat: np.ndarray, x_ref: np.ndarray) -> float:
    """``RMSE / (max(ref) - min(ref))`` over the finite reference (NaN for a constant one)."""
    r = np.asarray(x_ref, dtype=np.float64)
    r = r[np.isfinite(r)]
    if r.size == 0:
        return math.nan
    span = float(r.max() - r.min())
    return rmse(x_hat, x_ref) / span if span > 0.0 else math.nan


def calibration(x_hat: np.ndarray, x_std: np.ndarray, x_ref: np.ndarray) -> Dict[str, float]:
    """How well ``N(x_hat, x_std^2)`` describes ``x_ref``, over the samples where all three are
    finite and ``x_std > 0``: ``coverage_1sigma`` / ``coverage_2sigma`` (fraction with
    ``|x_ref - x_hat| <= k x_std``), ``mean_nees`` (mean of ``((x_ref - x_hat) / x_std)^2``),
    ``nlpd`` (mean of ``ln(2 pi x_std^2) / 2 + z^2 / 2``) and ``samples``. All NaN (samples 0)
    when nothing can be scored. Same definitions as ``hbn_model::metrics::calibration``."""
    e = np.asarray(x_hat, dtype=np.float64)
    s = np.asarray(x_std, dtype=np.float64)
    r = np.asarray(x_ref, dtype=np.float64)
    if not (e.shape == s.shape == r.shape):
        raise ValueError(f"x_hat, x_std and x_ref differ in shape: {e.shape}, {s.shape}, {r.shape}")
    ok = np.isfinite(e) & np.isfinite(s) & np.isfinite(r) & (s > 0.0)
    n = int(ok.sum())
    if n == 0:
        nan = math.nan
        return {"coverage_1sigma": nan, "coverage_2sigma": nan, "mean_nees": nan, "nlpd": nan, "samples": 0}
    z = (r[ok] - e[ok]) / s[ok]
    return {
        "coverage_1sigma": float(np.mean(np.abs(z) <= 1.0)),
        "coverage_2sigma": float(np.mean(np.abs(z) <= 2.0)),
        "mean_nees": float(np.mean(z * z)),
        "nlpd": float(np.mean(0.5 * np.log(2.0 * math.pi * s[ok] ** 2) + 0.5 * z * z)),
        "samples": n,
    }


def score(x_hat: np.ndarray, x_std: Optional[np.ndarray], x_ref: np.ndarray) -> Dict[str, Optional[float]]:
    """All scores of one estimate: ``rmse``, ``nrmse`` and, when ``x_std`` is given, the
    :func:`calibration` fields; without ``x_std`` (a point estimate) those are ``None``."""
    out: Dict[str, Optional[float]] = {"rmse": rmse(x_hat, x_ref), "nrmse": nrmse(x_hat, x_ref)}
    if x_std is None:
        finite = np.isfinite(np.asarray(x_hat, dtype=np.float64)) & np.isfinite(np.asarray(x_ref, dtype=np.float64))
        out.update({"coverage_1sigma": None, "coverage_2sigma": None, "mean_nees": None, "nlpd": None})
        out["samples"] = int(finite.sum())  # those the RMSE used
    else:
        out.update(calibration(x_hat, x_std, x_ref))
    return out
