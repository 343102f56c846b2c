"""Baseline 1: the GP-EKF a researcher would write with scikit-learn and numpy.

Two ``GaussianProcessRegressor`` models with an SE-ARD kernel
(``ConstantKernel * RBF(ARD) + WhiteKernel``, ``normalize_y=True``), each fitted on 600 random
rows of the HBN's training sets (transition ``[x_{k-1}, x_{k-2}, u_{k-1}, u_{k-2}] -> x_k``,
sensor ``[x_{k-1}, y_{k-1}, x_k] -> y_k``), drive a plain EKF on the augmented state
``z_k = [x_k, x_{k-1}, s_k]`` (``s_k`` the noise-free sensor output, ``y_k = s_k + v_k``), with
the timing of hbn's filter (``docs/ekf.md``: the estimate at step ``k`` has used ``y_k``).

* Jacobians: the analytic gradient of the GP mean (RBF kernel), checked against finite
  differences in the tests.
* Noise: ``Q = G q_x G^T + diag(0, 0, q_s)`` with ``q_x`` the transition GP's latent predictive
  variance plus its learned white noise, ``q_s`` the sensor GP's latent variance, and
  ``R`` the sensor GP's learned white noise.
* Initial state "from the first measurement": ``s_0 = y_0`` (variance ``R``), ``x_0 = x_{-1}``
  = mean of ``x`` over the 50 training samples whose ``y`` is nearest ``y_0``, with their
  variance (fully correlated), as hbn does, so that the comparison is about the models.
* No guards beyond what any careful EKF has: a symmetric Joseph-form update, the update
  skipped when the innovation variance is not positive or a measurement is not finite, and a
  missing input replaced by the last one. (hbn adds noise floors from the GPs' leave-one-out
  error, a state box, Jacobian and covariance bounds: see ``docs/ekf.md``.)
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Dict, Sequence, Tuple

import numpy as np
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel

from common import Log, sensor_rows, subsample, transition_rows

#: Rows per GP: the size of GP a researcher fits with scikit-learn in a few seconds.
GP_ROWS = 600
#: Training samples whose ``y`` is nearest the first measurement, for the initial ``x``.
INIT_NEIGHBOURS = 50


class SkGP:
    """A scikit-learn SE-ARD GP with the three predictions the EKF needs at one input: mean,
    latent variance (without the white noise) and the analytic gradient of the mean.

    ``fit`` uses ``ConstantKernel(1) * RBF(ones(d)) + WhiteKernel(0.1)`` with scikit-learn's
    default bounds, ``normalize_y=True`` and ``n_starts`` optimiser starts in all (the first
    from those values, the others random; 1 = scikit-learn's default).
    """

    def __init__(self, n_starts: int = 1, seed: int = 0) -> None:
        self.n_starts = n_starts
        self.seed = seed
        self.gpr: GaussianProcessRegressor

    def fit(self, X: np.ndarray, t: np.ndarray) -> "SkGP":
        """Fits the GP (maximum marginal likelihood) and caches what prediction needs."""
        d = X.shape[1]
        # scikit-learn's default bounds (1e-5..1e5 for every hyperparameter).
        kernel = ConstantKernel(1.0) * RBF(np.ones(d)) + WhiteKernel(0.1)
        self.gpr = GaussianProcessRegressor(
            kernel=kernel,
            normalize_y=True,
            n_restarts_optimizer=max(0, self.n_starts - 1),
            random_state=self.seed,
        ).fit(X, t)
        k = self.gpr.kernel_
        self.sf2 = float(k.k1.k1.constant_value)
        self.ell = np.asarray(k.k1.k2.length_scale, dtype=np.float64).reshape(-1) * np.ones(d)
        self.white = float(k.k2.noise_level)
        self.X = np.asarray(self.gpr.X_train_, dtype=np.float64)
        self.alpha = np.asarray(self.gpr.alpha_, dtype=np.float64).reshape(-1)
        self.L = np.asarray(self.gpr.L_, dtype=np.float64)
        # Inverse of the Cholesky factor once, so the variance is one mat-vec per prediction.
        self.Linv = np.linalg.solve(self.L, np.eye(self.L.shape[0]))
        self.y_mean = float(np.asarray(self.gpr._y_train_mean).reshape(-1)[0])
        self.y_std = float(np.asarray(self.gpr._y_train_std).reshape(-1)[0])
        return self

    @property
    def noise_var(self) -> float:
        """The learned white-noise variance in the target's units."""
        return self.white * self.y_std**2

    def predict(self, x: np.ndarray) -> Tuple[float, float, np.ndarray]:
        """Mean, latent variance (target units, without the white noise) and mean gradient
        (``d mean / d x``) at one input ``x`` of shape ``(d,)``."""
        diff = x[None, :] - self.X  # (n, d)
        kv = self.sf2 * np.exp(-0.5 * np.sum((diff / self.ell) ** 2, axis=1))
        mean = self.y_mean + self.y_std * float(kv @ self.alpha)
        v = self.Linv @ kv
        var = max(self.sf2 - float(v @ v), 0.0) * self.y_std**2
        grad = -self.y_std * ((kv * self.alpha) @ diff) / self.ell**2
        return mean, var, grad


@dataclass
class GpEkfModel:
    """The two fitted GPs plus the training pairs ``(y, x)`` used for the initial state."""

    transition: SkGP
    sensor: SkGP
    init_y: np.ndarray
    init_x: np.ndarray
    x_span: float


def fit(logs: Sequence[Log], seed: int = 0, rows: int = GP_ROWS, n_starts: int = 1) -> GpEkfModel:
    """Fits both GPs on ``rows`` random rows of each training set built from ``logs``."""
    rng = np.random.default_rng(seed)
    Xd, td = subsample(*transition_rows(logs), rows, rng)
    Xs, ts = subsample(*sensor_rows(logs), rows, rng)
    gd = SkGP(n_starts, seed).fit(Xd, td)
    gs = SkGP(n_starts, seed + 1).fit(Xs, ts)
    ys = np.concatenate([lg.y for lg in logs])
    xs = np.concatenate([lg.x for lg in logs])
    ok = np.isfinite(ys) & np.isfinite(xs)
    span = float(np.ptp(xs[ok])) if ok.any() else 1.0
    return GpEkfModel(gd, gs, ys[ok], xs[ok], span if span > 0 else 1.0)


def initial_x(model: GpEkfModel, y0: float) -> Tuple[float, float]:
    """Prior of ``x_0`` from the first measurement: mean and variance of ``x`` over the
    training samples whose ``y`` is nearest ``y0`` (variance at least ``1e-4 span(x)^2``)."""
    near = np.argsort(np.abs(model.init_y - y0), kind="stable")[:INIT_NEIGHBOURS]
    xs = model.init_x[near]
    return float(xs.mean()), max(float(xs.var()), 1e-4 * model.x_span**2)


def estimate(model: GpEkfModel, u: np.ndarray, y: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Runs the EKF over ``(u, y)`` and returns the per-step estimate of ``x`` and its
    standard deviation (``x_k`` has used ``u_0..u_{k-1}`` and ``y_0..y_k``)."""
    n = len(u)
    x_hat, x_std = np.full(n, np.nan), np.full(n, np.nan)
    R = model.sensor.noise_var
    y0 = next((float(v) for v in y if np.isfinite(v)), float(model.init_y.mean()))
    m0, v0 = initial_x(model, y0)
    z = np.array([m0, m0, y0])
    P = np.array([[v0, v0, 0.0], [v0, v0, 0.0], [0.0, 0.0, R]])
    x_hat[0], x_std[0] = z[0], math.sqrt(P[0, 0])
    H = np.array([0.0, 0.0, 1.0])
    u = np.asarray(u, dtype=np.float64).copy()
    for k in range(1, n):  # a missing input holds the last one
        if not np.isfinite(u[k]):
            u[k] = u[k - 1]
    for k in range(1, n):
        u1, u2 = u[k - 1], u[k - 2] if k >= 2 else u[0]
        # Predict: x_k from the transition GP, then s_k from the sensor GP at the new x_k.
        mx, vx, gx = model.transition.predict(np.array([z[0], z[1], u1, u2]))
        ms, vs, gs = model.sensor.predict(np.array([z[0], z[2], mx]))
        a1, a2 = gx[0], gx[1]
        c, e, f = gs
        F = np.array([[a1, a2, 0.0], [1.0, 0.0, 0.0], [c + f * a1, f * a2, e]])
        G = np.array([1.0, 0.0, f])
        Q = np.outer(G, G) * (vx + model.transition.noise_var) + np.diag([0.0, 0.0, vs])
        z = np.array([mx, z[0], ms])
        P = F @ P @ F.T + Q
        # Update with y_k (Joseph form).
        S = P[2, 2] + R
        if np.isfinite(y[k]) and S > 0.0:
            K = P[:, 2] / S
            z = z + K * (y[k] - z[2])
            IKH = np.eye(3) - np.outer(K, H)
            P = IKH @ P @ IKH.T + R * np.outer(K, K)
        P = 0.5 * (P + P.T)
        x_hat[k], x_std[k] = z[0], math.sqrt(max(P[0, 0], 0.0))
    return x_hat, x_std


def run(
    train: Sequence[Log], test: Log, seed: int = 0, rows: int = GP_ROWS, n_starts: int = 1
) -> Dict[str, object]:
    """Fits on ``train``, estimates on ``test``; returns ``x``, ``x_std`` and the seconds each
    phase took (``train_seconds``, ``estimate_seconds``) plus the fitted kernels."""
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
        "kernels": {"transition": str(model.transition.gpr.kernel_), "sensor": str(model.sensor.gpr.kernel_)},
    }
