"""Baseline 3: a NARX network, scikit-learn's ``MLPRegressor`` on windows of ``u`` and ``y``.

The estimate of ``x_k`` is an MLP's output on the standardised window
``[u_{k-W+1} .. u_k, y_{k-W+1} .. y_k]``: causal, it reads nothing after ``k``. Before the
window fills (``k < W - 1``) the first sample of the log stands for the missing past; a
missing sample (NaN) becomes the training mean (0 after standardising), as a held input would.

Training (all from the training logs; the test log is never seen):

* ``u``, ``y`` and ``x`` standardised with the mean and standard deviation of the training logs;
* windows never straddle two logs;
* the window length ``W`` and the hidden width are chosen on held-out data: each candidate
  (``windows`` x ``widths``) is trained on the first three quarters of every training log and
  scored (MSE) on the last quarter of each (an input segment it never trained on; its windows
  read the samples just before it, as at run time); the candidate with the lowest held-out MSE
  is refitted on all the training data;
* one hidden layer with tanh units, L-BFGS (deterministic, no early stopping, a fixed
  ``random_state``), L2 penalty ``alpha``; BLAS on one thread (set by ``run.py``).

No standard deviation: ``x_std`` is None, so coverage, NEES and NLPD are ``None``.
"""

from __future__ import annotations

import dataclasses
import time
import warnings
from dataclasses import dataclass
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from common import Log


@dataclass(frozen=True)
class NarxConfig:
    """Candidates and training settings of the NARX baseline."""

    windows: Tuple[int, ...] = (5, 10, 20)
    widths: Tuple[int, ...] = (32, 64)
    holdout: float = 0.25
    alpha: float = 1e-4
    max_iter: int = 400


class _Scaler:
    """Means and standard deviations of ``u``, ``y`` and ``x`` over the training logs."""

    def __init__(self, logs: Sequence[Log]) -> None:
        def ms(a: np.ndarray) -> Tuple[float, float]:
            a = a[np.isfinite(a)]
            if a.size == 0:
                return 0.0, 1.0
            sd = float(a.std())
            return float(a.mean()), sd if sd > 0 else 1.0

        self.u = ms(np.concatenate([lg.u for lg in logs]))
        self.y = ms(np.concatenate([lg.y for lg in logs]))
        self.x = ms(np.concatenate([lg.x for lg in logs]))

    @staticmethod
    def _z(a: np.ndarray, m: Tuple[float, float]) -> np.ndarray:
        return np.nan_to_num((np.asarray(a, float) - m[0]) / m[1], nan=0.0, posinf=0.0, neginf=0.0)

    def windows(self, lg: Log, w: int) -> np.ndarray:
        """The ``(len(lg), 2 w)`` causal windows of one log: row ``k`` is
        ``[u_{k-w+1} .. u_k, y_{k-w+1} .. y_k]`` standardised (the first sample repeated before
        the log starts)."""
        cols = []
        for sig in (self._z(lg.u, self.u), self._z(lg.y, self.y)):
            padded = np.concatenate([np.full(w - 1, sig[0] if sig.size else 0.0), sig])
            cols.append(np.lib.stride_tricks.sliding_window_view(padded, w))
        return np.hstack(cols)

    def target(self, x: np.ndarray) -> np.ndarray:
        return (np.asarray(x, float) - self.x[0]) / self.x[1]


def _rows(scaler: _Scaler, logs: Sequence[Tuple[Log, int, int]], w: int) -> Tuple[np.ndarray, np.ndarray]:
    """Windows and standardised targets of samples ``lo..hi`` of each log (windows read the
    samples before ``lo`` too); rows with a non-finite target are left out."""
    xs, ts = [], []
    for lg, lo, hi in logs:
        f = scaler.windows(lg, w)[lo:hi]
        t = scaler.target(lg.x)[lo:hi]
        ok = np.isfinite(t)
        xs.append(f[ok])
        ts.append(t[ok])
    return np.vstack(xs), np.concatenate(ts)


def _fit(X: np.ndarray, t: np.ndarray, width: int, cfg: NarxConfig, seed: int) -> Any:
    from sklearn.exceptions import ConvergenceWarning
    from sklearn.neural_network import MLPRegressor

    net = MLPRegressor(
        hidden_layer_sizes=(width,),
        activation="tanh",
        solver="lbfgs",
        alpha=cfg.alpha,
        max_iter=cfg.max_iter,
        early_stopping=False,
        random_state=seed,
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        net.fit(X, t)
    return net


def run(train: Sequence[Log], test: Log, seed: int = 0, config: Optional[NarxConfig] = None) -> Dict[str, Any]:
    """Chooses ``W`` and the width on held-out data, refits on all of ``train`` and predicts
    ``x`` causally on ``test``.

    Returns ``x`` (``x_std`` is None), ``train_seconds``, ``estimate_seconds``, ``window`` and
    ``width`` (the chosen ones), ``holdout_mse`` (``{"W=..,width=..": MSE}``, standardised
    units) and ``config``.
    """
    cfg = config or NarxConfig()
    t0 = time.perf_counter()
    scaler = _Scaler(train)
    fit_part, held_part = [], []
    for lg in train:
        n = len(lg)
        cut = int(round(n * (1.0 - cfg.holdout)))
        fit_part.append((lg, 0, cut))
        if n - cut >= 1:
            held_part.append((lg, cut, n))
    scores: Dict[str, float] = {}
    best: Optional[Tuple[float, int, int]] = None
    if len(cfg.windows) * len(cfg.widths) > 1 and held_part:
        for w in cfg.windows:
            Xf, tf = _rows(scaler, fit_part, w)
            Xh, th = _rows(scaler, held_part, w)
            for width in cfg.widths:
                net = _fit(Xf, tf, width, cfg, seed)
                mse = float(np.mean((net.predict(Xh) - th) ** 2))
                scores[f"W={w},width={width}"] = mse
                if np.isfinite(mse) and (best is None or mse < best[0]):
                    best = (mse, w, width)
    _, w, width = best if best is not None else (0.0, cfg.windows[0], cfg.widths[0])
    X, t = _rows(scaler, [(lg, 0, len(lg)) for lg in train], w)
    net = _fit(X, t, width, cfg, seed)
    t1 = time.perf_counter()
    x_hat = net.predict(scaler.windows(test, w)) * scaler.x[1] + scaler.x[0]
    t2 = time.perf_counter()
    return {
        "x": np.asarray(x_hat, float),
        "x_std": None,
        "train_seconds": t1 - t0,
        "estimate_seconds": t2 - t1,
        "window": w,
        "width": width,
        "holdout_mse": scores,
        "config": {k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(cfg).items()},
    }
