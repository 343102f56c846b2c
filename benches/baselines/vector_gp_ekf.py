"""The vector GP-EKF: ``gp_ekf.py`` grown to several inputs, a vector state and several sensors.

The design is the scalar baseline's, one GP per output, as a researcher would extend it with
scikit-learn and numpy (``docs/baselines.md``), for ``u`` in R^du, ``x`` in R^dx, ``y`` in R^dy:

* One SE-ARD ``GaussianProcessRegressor`` (``gp_ekf.SkGP``: ``ConstantKernel * RBF(ARD) +
  WhiteKernel``, ``normalize_y=True``, scikit-learn's default bounds) **per state component**
  ``i`` on rows ``[x_{k-1}, x_{k-2}, u_{k-1}, u_{k-2}] -> x^i_k`` (every component, every
  input: ``2 dx + 2 du`` inputs), and one **per sensor** ``j`` on rows
  ``[x_{k-1}, y^j_{k-1}, x_k] -> y^j_k`` (``2 dx + 1`` inputs); each GP on its own 600 random
  rows of the training logs (no row straddles two logs; rows with a missing value dropped).
* A plain EKF on the augmented state ``z_k = [x_k, x_{k-1}, s_k]`` of dimension
  ``2 dx + dy`` (``s_k`` the noise-free sensor outputs, ``y_k = s_k + v_k``), with the timing
  of hbn's filter (the estimate at step ``k`` has used ``y_k``); in the sensor GPs the filtered
  ``s^j_{k-1}`` stands for ``y^j_{k-1}``, as in the scalar baseline.
* Jacobians: the analytic gradients of the GP means (``SkGP.predict``), chained through
  ``x_k`` into the sensor rows; checked against finite differences in the tests.
* Noise: ``Q = G diag(q_x) G^T + diag(0, 0, q_s)`` with ``q_x^i`` the transition GP's latent
  variance plus its learned white noise, ``G = [I; 0; d s / d x_k]`` (the process noise of
  ``x_k`` reaches ``s_k`` through the sensor GPs) and ``q_s^j`` the sensor GP's latent
  variance; ``R = diag`` of the sensor GPs' learned white noise.
* The update reads every sensor at once (a ``dy x dy`` innovation covariance) in Joseph form; a
  sensor whose sample is not finite sits the step out (the update uses the others; with none,
  there is no update), and so does the whole step when the innovation covariance is not
  positive definite. A missing input holds the last one.
* Initial state "from the first measurement", as the scalar baseline and hbn do: ``s_0 = y_0``
  (variance ``R``; a sensor without a finite first sample takes its first finite one), and
  ``x_0 = x_{-1}`` the mean of ``x`` over the 50 training samples whose ``y`` is nearest
  ``y_0`` (each sensor scaled by its training standard deviation), with their covariance (fully
  correlated between ``x_0`` and ``x_{-1}``; each variance at least ``1e-4 span(x^i)^2``).

With ``du = dx = dy = 1`` this is ``gp_ekf.py`` step for step (a test checks it). No guard of
hbn's (noise floors, state box, Jacobian and covariance bounds, outlier gate: ``docs/ekf.md``)
is added, so the comparison is about the models and the filter as a researcher would write
them.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from common import native_rate, subsample
from gp_ekf import GP_ROWS, INIT_NEIGHBOURS, SkGP

#: Most inputs, state components and sensors looked for in a log of ``hbn simulate``.
MAX_SIGNALS = 8


@dataclass(frozen=True)
class VectorLog:
    """One logged trajectory on a uniform grid: inputs ``u`` ``(T, du)``, state ``x``
    ``(T, dx)``, sensor outputs ``y`` ``(T, dy)``."""

    u: np.ndarray
    x: np.ndarray
    y: np.ndarray
    rate: float
    path: str = ""

    def __len__(self) -> int:
        return int(self.u.shape[0])

    @property
    def dims(self) -> Tuple[int, int, int]:
        """``(du, dx, dy)``."""
        return int(self.u.shape[1]), int(self.x.shape[1]), int(self.y.shape[1])


@dataclass(frozen=True)
class VectorPaths:
    """Foxglove message paths of every input, state component and sensor, in order."""

    u: Tuple[str, ...]
    x: Tuple[str, ...]
    y: Tuple[str, ...]


def simulated_paths(path: str) -> VectorPaths:
    """The signals of a log of ``hbn simulate --system finger|arm`` (as ``hbn train`` finds
    them): the topics ``/input0``, ``/input1``, ... and ``/sensor0``, ... present in the log
    (field ``data``), and the state fields ``x0``, ``x1``, ... of ``/state`` that it can read.
    ``ValueError`` if the log has no ``/input0`` topic or no readable state field."""
    import hbn

    topics = {str(t["topic"]) for t in hbn.list_topics(path)}

    def count(prefix: str) -> int:
        return next((i for i in range(MAX_SIGNALS) if f"{prefix}{i}" not in topics), MAX_SIGNALS)

    du, dy = count("/input"), count("/sensor")
    if du == 0 or dy == 0:
        raise ValueError(f"{path}: no /input0 or /sensor0 topic: not a multi-signal log of `hbn simulate`")
    dx = 0
    for i in range(MAX_SIGNALS):
        try:
            hbn.read_mcap(path, {"u": "/input0.data", "x": f"/state.x{i}"})
        except Exception:  # the field is absent: the state has i components
            break
        dx = i + 1
    if dx == 0:
        raise ValueError(f"{path}: /state has no field x0")
    return VectorPaths(
        u=tuple(f"/input{a}.data" for a in range(du)),
        x=tuple(f"/state.x{i}" for i in range(dx)),
        y=tuple(f"/sensor{j}.data" for j in range(dy)),
    )


def read_vector_log(path: str, paths: VectorPaths, rate: Optional[float] = None) -> VectorLog:
    """Reads every signal of ``paths`` from one MCAP log with :func:`hbn.read_mcap`, on the grid
    of ``rate`` Hz (``None``: the log's native rate, that of the first input)."""
    import hbn

    names: Dict[str, str] = {}
    for key, group in (("u", paths.u), ("x", paths.x), ("y", paths.y)):
        for i, p in enumerate(group):
            names[f"{key}{i}"] = p
    d = hbn.read_mcap(path, names, rate_hz=rate)
    r = native_rate(d["t"]) if rate is None else float(rate)

    def stack(key: str, n: int) -> np.ndarray:
        return np.column_stack([np.asarray(d[f"{key}{i}"], dtype=np.float64) for i in range(n)])

    return VectorLog(
        u=stack("u", len(paths.u)), x=stack("x", len(paths.x)), y=stack("y", len(paths.y)), rate=r, path=str(path)
    )


def read_vector_logs(
    train_paths: Sequence[str], test_path: str, paths: Optional[VectorPaths] = None
) -> Tuple[List[VectorLog], VectorLog]:
    """Reads the training logs and the test log on ONE grid, the native rate of the first
    training log (as ``common.read_logs``). ``paths``: ``None`` finds the signals of a log of
    ``hbn simulate`` in the first training log (:func:`simulated_paths`)."""
    if len(train_paths) == 0:
        raise ValueError("at least one training log is needed")
    paths = simulated_paths(train_paths[0]) if paths is None else paths
    first = read_vector_log(train_paths[0], paths)
    train = [first] + [read_vector_log(p, paths, rate=first.rate) for p in train_paths[1:]]
    return train, read_vector_log(test_path, paths, rate=first.rate)


# ------------------------------------------------------------------------------------------------
# Training sets
# ------------------------------------------------------------------------------------------------


def _check_dims(logs: Sequence[VectorLog]) -> Tuple[int, int, int]:
    if not logs:
        raise ValueError("no training log")
    dims = {lg.dims for lg in logs}
    if len(dims) != 1:
        raise ValueError(f"the logs differ in (du, dx, dy): {sorted(dims)}")
    return dims.pop()


def transition_rows(logs: Sequence[VectorLog]) -> Tuple[np.ndarray, np.ndarray]:
    """The transition training set: inputs ``[x_{k-1}, x_{k-2}, u_{k-1}, u_{k-2}]`` (every
    component, every input: ``2 dx + 2 du`` columns), targets ``x_k`` ``(rows, dx)``, for
    ``k >= 2`` of every log (no row straddles two logs)."""
    _check_dims(logs)
    X, t = [], []
    for lg in logs:
        if len(lg) < 3:
            continue
        X.append(np.hstack([lg.x[1:-1], lg.x[:-2], lg.u[1:-1], lg.u[:-2]]))
        t.append(lg.x[2:])
    if not X:
        raise ValueError("no log has the 3 samples a transition row needs")
    return np.vstack(X), np.vstack(t)


def sensor_rows(logs: Sequence[VectorLog], j: int) -> Tuple[np.ndarray, np.ndarray]:
    """Sensor ``j``'s training set: inputs ``[x_{k-1}, y^j_{k-1}, x_k]`` (``2 dx + 1``
    columns), target ``y^j_k``, for ``k >= 2`` of every log (no row straddles two logs)."""
    _check_dims(logs)
    X, t = [], []
    for lg in logs:
        if len(lg) < 3:
            continue
        X.append(np.hstack([lg.x[1:-1], lg.y[1:-1, j : j + 1], lg.x[2:]]))
        t.append(lg.y[2:, j])
    if not X:
        raise ValueError("no log has the 3 samples a sensor row needs")
    return np.vstack(X), np.concatenate(t)


# ------------------------------------------------------------------------------------------------
# Model
# ------------------------------------------------------------------------------------------------


@dataclass
class VectorGpEkfModel:
    """The fitted GPs (one per state component, one per sensor) plus the training pairs
    ``(y, x)`` used for the initial state. ``transition`` and ``sensor`` hold anything with
    ``SkGP``'s ``predict`` and ``noise_var`` (the tests use linear stand-ins)."""

    transition: List[SkGP]
    sensor: List[SkGP]
    init_y: np.ndarray
    init_x: np.ndarray
    x_span: np.ndarray

    @property
    def dx(self) -> int:
        """State components."""
        return len(self.transition)

    @property
    def dy(self) -> int:
        """Sensors."""
        return len(self.sensor)

    @property
    def r(self) -> np.ndarray:
        """The sensors' noise variances (the diagonal of ``R``)."""
        return np.array([g.noise_var for g in self.sensor], dtype=np.float64)


def fit(logs: Sequence[VectorLog], seed: int = 0, rows: int = GP_ROWS, n_starts: int = 1) -> VectorGpEkfModel:
    """Fits one GP per state component and one per sensor, each on its own ``rows`` random
    rows of its training set built from ``logs`` (transition GP ``i`` seeded ``seed + i``,
    sensor GP ``j`` ``seed + dx + j``)."""
    _, dx, dy = _check_dims(logs)
    rng = np.random.default_rng(seed)
    Xd, td = transition_rows(logs)
    trans = []
    for i in range(dx):
        X, t = subsample(Xd, td[:, i], rows, rng)
        trans.append(SkGP(n_starts, seed + i).fit(X, t))
    sens = []
    for j in range(dy):
        X, t = subsample(*sensor_rows(logs, j), rows, rng)
        sens.append(SkGP(n_starts, seed + dx + j).fit(X, t))
    ys = np.vstack([lg.y for lg in logs])
    xs = np.vstack([lg.x for lg in logs])
    ok = np.all(np.isfinite(ys), axis=1) & np.all(np.isfinite(xs), axis=1)
    if not ok.any():
        raise ValueError("no training sample has every x and y finite (needed for the initial state)")
    span = np.ptp(xs[ok], axis=0)
    return VectorGpEkfModel(trans, sens, ys[ok], xs[ok], np.where(span > 0, span, 1.0))


def initial_x(model: VectorGpEkfModel, y0: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Prior of ``x_0`` from the first measurement ``y0`` ``(dy,)``: mean and covariance
    ``(dx, dx)`` of ``x`` over the training samples whose ``y`` is nearest ``y0`` (Euclidean,
    each sensor divided by its training standard deviation, over the finite entries of ``y0``);
    each variance is raised to at least ``1e-4 span(x^i)^2``."""
    y0 = np.asarray(y0, dtype=np.float64)
    ok = np.isfinite(y0)
    if ok.any():
        sd = model.init_y.std(axis=0)
        sd = np.where(sd > 0, sd, 1.0)
        dist = np.sqrt(np.sum(((model.init_y[:, ok] - y0[ok]) / sd[ok]) ** 2, axis=1))
        near = np.argsort(dist, kind="stable")[:INIT_NEIGHBOURS]
    else:
        near = np.arange(model.init_x.shape[0])
    xs = model.init_x[near]
    mean = xs.mean(axis=0)
    dev = xs - mean
    cov = dev.T @ dev / xs.shape[0]
    floor = 1e-4 * model.x_span**2
    cov = cov + np.diag(np.maximum(floor - np.diag(cov), 0.0))
    return mean, cov


def predict_step(
    model: VectorGpEkfModel, z: np.ndarray, u1: np.ndarray, u2: np.ndarray
) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One EKF prediction from ``z_{k-1} = [x_{k-1}, x_{k-2}, s_{k-1}]`` with inputs
    ``u_{k-1}``, ``u_{k-2}``: the predicted mean ``z_k``, the Jacobian ``F = d z_k / d z_{k-1}``
    (``n x n``, ``n = 2 dx + dy``) and the process noise ``Q``."""
    dx, dy = model.dx, model.dy
    n = 2 * dx + dy
    a = np.concatenate([z[: 2 * dx], u1, u2])
    mx, qx = np.empty(dx), np.empty(dx)
    A = np.empty((dx, 2 * dx))  # d x_k / d [x_{k-1}, x_{k-2}]
    for i, gp in enumerate(model.transition):
        m, v, g = gp.predict(a)
        mx[i], qx[i], A[i] = m, v + gp.noise_var, g[: 2 * dx]
    ms, qs = np.empty(dy), np.empty(dy)
    C = np.empty((dy, dx))  # d s_k / d x_{k-1}, directly
    E = np.empty(dy)  # d s^j_k / d s^j_{k-1}
    Fs = np.empty((dy, dx))  # d s_k / d x_k
    for j, gp in enumerate(model.sensor):
        m, v, g = gp.predict(np.concatenate([z[:dx], z[2 * dx + j : 2 * dx + j + 1], mx]))
        ms[j], qs[j] = m, v
        C[j], E[j], Fs[j] = g[:dx], g[dx], g[dx + 1 :]
    F = np.zeros((n, n))
    F[:dx, : 2 * dx] = A
    F[dx : 2 * dx, :dx] = np.eye(dx)
    F[2 * dx :, : 2 * dx] = Fs @ A
    F[2 * dx :, :dx] += C
    F[2 * dx :, 2 * dx :] = np.diag(E)
    G = np.zeros((n, dx))
    G[:dx] = np.eye(dx)
    G[2 * dx :] = Fs
    Q = (G * qx) @ G.T
    Q[2 * dx :, 2 * dx :] += np.diag(qs)
    return np.concatenate([mx, z[:dx], ms]), F, Q


def update_step(
    model: VectorGpEkfModel, z: np.ndarray, P: np.ndarray, y: np.ndarray
) -> Tuple[np.ndarray, np.ndarray, int]:
    """The Joseph-form update of ``(z, P)`` with the finite entries of ``y`` ``(dy,)``; returns
    the updated ``z``, ``P`` and the number of sensors read (0: no update, when no sample is
    finite or the innovation covariance is not positive definite)."""
    dx = model.dx
    read = np.flatnonzero(np.isfinite(y))
    if read.size == 0:
        return z, P, 0
    h = 2 * dx + read
    R = np.diag(model.r[read])
    S = P[np.ix_(h, h)] + R
    try:
        np.linalg.cholesky(S)
    except np.linalg.LinAlgError:
        return z, P, 0
    K = np.linalg.solve(S, P[h, :]).T  # P H^T S^-1 (S symmetric)
    z = z + K @ (y[read] - z[h])
    IKH = np.eye(P.shape[0])
    IKH[:, h] -= K
    P = IKH @ P @ IKH.T + K @ R @ K.T
    return z, P, int(read.size)


def _held(a: np.ndarray) -> np.ndarray:
    """``a`` ``(T, d)`` with each non-finite entry replaced by the last finite one of its column
    (a missing input holds the last one; a leading gap takes the first finite value, or 0)."""
    a = np.array(a, dtype=np.float64, copy=True)
    for c in range(a.shape[1]):
        col = a[:, c]
        ok = np.isfinite(col)
        if not ok.any():
            col[:] = 0.0
            continue
        first = int(np.argmax(ok))
        col[:first] = col[first]
        for k in range(first + 1, col.shape[0]):
            if not ok[k]:
                col[k] = col[k - 1]
    return a


def estimate(model: VectorGpEkfModel, u: np.ndarray, y: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Runs the EKF over ``u`` ``(T, du)`` and ``y`` ``(T, dy)`` and returns the per-step
    estimate of ``x`` and its standard deviation, both ``(T, dx)`` (``x_k`` has used
    ``u_0..u_{k-1}`` and ``y_0..y_k``)."""
    u = np.asarray(u, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if u.ndim == 1:
        u = u[:, None]
    if y.ndim == 1:
        y = y[:, None]
    dx, dy = model.dx, model.dy
    if y.shape[1] != dy:
        raise ValueError(f"y has {y.shape[1]} sensors, the model {dy}")
    n = len(u)
    x_hat, x_std = np.full((n, dx), np.nan), np.full((n, dx), np.nan)
    if n == 0:
        return x_hat, x_std
    R = model.r
    # s_0 = y_0; a sensor without a finite first sample takes its first finite one.
    y0 = np.empty(dy)
    for j in range(dy):
        fin = y[np.isfinite(y[:, j]), j]
        y0[j] = fin[0] if fin.size else float(model.init_y[:, j].mean())
    m0, C0 = initial_x(model, y0)
    z = np.concatenate([m0, m0, y0])
    P = np.zeros((2 * dx + dy, 2 * dx + dy))
    P[: 2 * dx, : 2 * dx] = np.block([[C0, C0], [C0, C0]])
    P[2 * dx :, 2 * dx :] = np.diag(R)
    x_hat[0], x_std[0] = z[:dx], np.sqrt(np.diag(P)[:dx])
    u = _held(u)
    for k in range(1, n):
        u2 = u[k - 2] if k >= 2 else u[0]
        z, F, Q = predict_step(model, z, u[k - 1], u2)
        P = F @ P @ F.T + Q
        z, P, _ = update_step(model, z, P, y[k])
        P = 0.5 * (P + P.T)
        x_hat[k], x_std[k] = z[:dx], np.sqrt(np.maximum(np.diag(P)[:dx], 0.0))
    return x_hat, x_std


def run(
    train: Sequence[VectorLog], test: VectorLog, seed: int = 0, rows: int = GP_ROWS, n_starts: int = 1
) -> Dict[str, object]:
    """Fits on ``train``, estimates on ``test``; returns ``x`` and ``x_std`` ``(T, dx)``, the
    seconds each phase took (``train_seconds``, ``estimate_seconds``) and the fitted kernels."""
    t0 = time.perf_counter()
    model = fit(train, seed=seed, rows=rows, n_starts=n_starts)
    t1 = time.perf_counter()
    x, s = estimate(model, test.u, test.y)
    t2 = time.perf_counter()
    return {
        "x": x,
        "x_std": s,
        "train_seconds": t1 - t0,
        "estimate_seconds": t2 - t1,
        "kernels": {
            "transition": [str(g.gpr.kernel_) for g in model.transition],
            "sensor": [str(g.gpr.kernel_) for g in model.sensor],
        },
    }
