#!/usr/bin/env python3
"""A standalone numpy implementation of hbn's plain EKF, and a benchmark against ``hbn``.

The filter reads the model file (``hbn train --out`` / ``HysteresisModel.save``: JSON) directly
and reimplements, with numpy only:

* GP prediction (``crates/hbn-core/src/gp.rs``): raw input -> standardised ``z`` -> kernel
  features ``u* = L phi(z)`` (``crates/hbn-core/src/kernel.rs``), ``k_i = s_f^2 f(|u_i - u*|^2)
  D(g*, g_i)``, mean ``= m_y + s_y k.alpha``, variance ``= s_y^2 (k** - |L^-1 k|^2)`` (exact
  GP) or ``s_y^2 (k** - |L^-1 k|^2 + |C k|^2)`` (sparse GP, ``docs/sparse.md``), mean
  gradient by the chain rule through the features and the standardisation;
* the EKF step (``crates/hbn-core/src/ekf.rs``): state ``[x_k, x_{k-1}, s_k]``, transition and
  sensor linearisation, the guards (state box, Jacobian bound, noise floors, Gershgorin test and
  eigenvalue clamp of P, Joseph update) and the default settings of ``HysteresisModel::ekf_config``
  (``crates/hbn-model/src/model.rs``).

Kernels: every kernel a model file holds (``matern52``, ``se-ard``, ``se`` and ``thesis``: the
profile, an isotropic, ARD or Mahalanobis metric, the tanh input warping and the
direction-advantage factor are each read from the file).

It is a per-sample filter, so a Python loop over samples with vectorised numpy inside each step
is the honest numpy baseline. The packed Cholesky factor is inverted once at load time, so the
variance is one dense mat-vec per prediction.

Usage::

    python benches/numpy_filter.py [--steps 2000] [--max-points 500] [--system duhem] [--inducing 64]

prints the per-step time of numpy and of ``hbn`` (the Python binding running the Rust filter,
same model, same data), their ratio, and ``max |x_numpy - x_hbn|``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
import time
from typing import Any, Dict, Optional, Tuple

import numpy as np

# ------------------------------------------------------------------------------------------------
# GP prediction (hbn-core gp.rs + kernel.rs)
# ------------------------------------------------------------------------------------------------

SQRT5 = math.sqrt(5.0)


class NumpyGP:
    """Prediction of one GP of the model file (mean, latent variance, mean gradient)."""

    def __init__(self, gp: Dict[str, Any]) -> None:
        spec = gp["kernel"]
        self.d = int(spec["dim"])
        self.profile = spec["profile"]  # "squared-exponential" | "matern52"
        self.metric = spec["metric"]  # "isotropic" | "ard" | "mahalanobis"
        self.warp_units = int(spec.get("warp-units", 0))
        self.direction = spec.get("direction")  # None or [a, b]
        theta = np.asarray(gp["theta"], dtype=np.float64)
        self.theta = theta
        self.sf2 = math.exp(theta[0])
        d = self.d
        # Metric factor L (M = L^T L): u = L p.
        if self.metric == "isotropic":
            self.L = np.eye(d) * math.exp(-theta[1])
            n_metric = 1
        elif self.metric == "ard":
            self.L = np.diag(np.exp(-theta[1 : 1 + d]))
            n_metric = d
        elif self.metric == "mahalanobis":
            w = np.asarray(gp["whiten"], dtype=np.float64).reshape(d, d)
            self.L = w * math.exp(-0.5 * theta[1])
            n_metric = 1
        else:
            raise ValueError(f"unknown metric {self.metric!r}")
        m = self.warp_units
        a_off = 1 + n_metric
        b_off = a_off + d * m
        if m > 0:
            self.warp_a = theta[a_off : a_off + d * m].reshape(d, m)
            self.warp_b = np.exp(theta[b_off : b_off + d * m]).reshape(d, m)
        self.in_mean = np.asarray(gp["input_mean"], dtype=np.float64)
        self.in_scale = np.asarray(gp["input_scale"], dtype=np.float64)
        self.out_mean = float(gp["output_mean"])
        self.out_scale = float(gp["output_scale"])
        # A linear prior mean's slopes in raw units (absent: a constant mean).
        self.linear = np.asarray(gp.get("linear", []), dtype=np.float64)
        self.noise_var_raw = float(gp["noise_variance"]) * self.out_scale**2
        n = len(gp["alpha"])
        self.n = n
        self.features = np.asarray(gp["features"], dtype=np.float64).reshape(n, d)
        self.alpha = np.asarray(gp["alpha"], dtype=np.float64)
        self.dirs = (
            np.asarray(gp["directions"], dtype=np.float64) if self.direction is not None else None
        )
        rows, cols = np.tril_indices(n)  # row-major lower triangle: the packed order

        def unpack(values: Any) -> np.ndarray:
            m = np.zeros((n, n))
            m[rows, cols] = np.asarray(values, dtype=np.float64)
            return m

        sparse = gp.get("sparse")
        if sparse is None:
            # Exact GP: the file leaves the Cholesky factor out (L L^T = K + s_n^2 I over the
            # support points); L^{-1} once, and the variance is |L^{-1} k|^2, one mat-vec.
            delta = self.features[:, None, :] - self.features[None, :, :]
            f, _ = self._profile(np.einsum("ijk,ijk->ij", delta, delta))
            dirf = 1.0 if self.dirs is None else 0.5 * (1.0 + np.outer(self.dirs, self.dirs))
            kmat = self.sf2 * f * dirf + float(gp["noise_variance"]) * np.eye(n)
            chol = np.linalg.cholesky(kmat)
            self.chol_inv = np.linalg.solve(chol, np.eye(n))
        else:
            # Sparse GP (docs/sparse.md): var = k** - |R k|^2 with R^T R = K_mm^{-1} - Sigma, the
            # folded factor the file stores.
            self.chol_inv = unpack(sparse["variance_factor"])

    def _profile(self, r2: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Kernel profile ``f(r2)`` and its slope ``df/dr2``."""
        if self.profile == "squared-exponential":
            f = np.exp(-0.5 * r2)
            return f, -0.5 * f
        r = np.sqrt(np.maximum(r2, 0.0))
        e = np.exp(-SQRT5 * r)
        return (1.0 + SQRT5 * r + (5.0 / 3.0) * r2) * e, -(5.0 / 6.0) * (1.0 + SQRT5 * r) * e

    def _features(self, z: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """``u = L phi(z)`` and ``du/dz`` (d x d)."""
        if self.warp_units == 0:
            return self.L @ z, self.L
        t = np.tanh(z[:, None] + self.warp_a)
        p = (self.warp_b * t).sum(axis=1)
        dp = (self.warp_b * (1.0 - t * t)).sum(axis=1)
        return self.L @ p, self.L * dp[None, :]

    def predict(self, x_raw: np.ndarray) -> Tuple[float, float, np.ndarray]:
        """(mean, variance, d mean / d x) at one raw input."""
        z = (x_raw - self.in_mean) / self.in_scale
        u_star, du_dz = self._features(z)
        delta = self.features - u_star
        r2 = np.einsum("ij,ij->i", delta, delta)
        f, df = self._profile(r2)
        if self.direction is not None:
            a, b = self.direction
            g = float(np.sign(x_raw[a] - x_raw[b]))
            dirf = 0.5 * (1.0 + g * self.dirs)
            kss = self.sf2 * 0.5 * (1.0 + g * g)
        else:
            dirf = 1.0
            kss = self.sf2
        k = self.sf2 * f * dirf
        c = self.sf2 * dirf * df
        mean_std = k @ self.alpha
        grad_u = (-2.0 * c * self.alpha) @ delta
        grad = self.out_scale * (grad_u @ du_dz) / self.in_scale
        v = self.chol_inv @ k
        reduction = v @ v
        var = self.out_scale**2 * max(kss - reduction, 0.0)
        mean = self.out_mean + self.out_scale * mean_std
        if self.linear.size:
            mean += float(self.linear @ (x_raw - self.in_mean))
            grad = grad + self.linear
        return mean, var, grad


# ------------------------------------------------------------------------------------------------
# EKF step (hbn-core ekf.rs) with the default settings of HysteresisModel::ekf_config
# ------------------------------------------------------------------------------------------------


def _span(st: Dict[str, float]) -> float:
    return max(st["max"] - st["min"], 1e-12 * max(abs(st["max"]), 1.0))


def ekf_config(model: Dict[str, Any]) -> Dict[str, Any]:
    """``HysteresisModel::ekf_config(Mode::Ekf)``, with the noise scales learned at training."""
    xs, ys = model["x_stats"], model["y_stats"]
    sx, sy = _span(xs), _span(ys)
    scales = model.get("tuning", {}).get("ekf", {"q": 1.0, "r": 1.0, "std": 1.0})
    return {
        "q_scale": float(scales["q"]),
        "r_scale": float(scales["r"]),
        "std_scale": float(scales["std"]),
        "q_floor": 1e-10 * sx * sx,
        "r_floor": 1e-10 * sy * sy,
        "qx_model_floor": float(model["transition"].get("loo_error_variance", 0.0)),
        "r_model_floor": float(model["sensor"].get("loo_error_variance", 0.0)),
        "p_min": 1e-14 * min(sx, sy) ** 2,
        "p_max": 4.0 * max(sx, sy) ** 2,
        "jac_max": 20.0 * max(sy / sx, sx / sy, 1.0),
        "innovation_min": 1e-14 * sy * sy,
        # hbn_model::OUTLIER_GATE: every trained model's filter ships with it.
        "nis_gate": 25.0,
        "x_bounds": (xs["min"] - 0.5 * sx, xs["max"] + 0.5 * sx),
        "y_bounds": (ys["min"] - 0.5 * sy, ys["max"] + 0.5 * sy),
        "x0_mean": xs["mean"],
        "x0_var": max(xs["var"], 1e-12 * sx * sx),
    }




def _clamp(v: float, b: Tuple[float, float]) -> float:
    if not math.isfinite(v):
        return 0.5 * (b[0] + b[1])
    return min(max(v, b[0]), b[1])


#: ``hbn_core::ekf::LOST_AFTER``: steps in a row whose transition prediction from the estimate
#: left the state box, after which the filter re-starts from the prior of x at the current
#: measurement.
LOST_AFTER = 10


def _clamp_jac(v: float, m: float) -> float:
    return min(max(v, -m), m) if math.isfinite(v) else 0.0


def _floor(v: float, fl: float) -> float:
    return v if (math.isfinite(v) and v >= fl) else fl


def _bound_cov(p: np.ndarray, lo: float, hi: float) -> np.ndarray:
    sym = (p + p.T) * 0.5
    if not np.all(np.isfinite(sym)):
        return np.eye(3) * hi
    diag = np.diag(sym)
    radius = np.abs(sym).sum(axis=1) - np.abs(diag)
    if np.all(diag - radius >= lo) and np.all(diag + radius <= hi):
        return sym
    vals, vecs = np.linalg.eigh(sym)
    clamped = np.clip(vals, lo, hi)
    if np.array_equal(clamped, vals):
        return sym
    out = (vecs * clamped) @ vecs.T
    return (out + out.T) * 0.5


def initial_state(model: Dict[str, Any], y0: float) -> Optional[Tuple[float, float]]:
    """``HysteresisModel::initial_state`` (``hbn_core::InitPrior``): mean and variance of x over the 50
    training samples whose y is nearest ``y0`` (ties by index)."""
    pairs = np.asarray(model.get("init_pairs", []), dtype=float).reshape(-1, 2)
    if not math.isfinite(y0) or len(pairs) == 0:
        return None
    dist = np.abs(pairs[:, 0] - y0)
    near = np.lexsort((np.arange(len(pairs)), dist))[:50]
    xs = pairs[near, 1]
    mean = float(xs.sum() / len(xs))
    var = float(((xs - mean) ** 2).sum() / len(xs))
    sx = _span(model["x_stats"])
    return mean, max(var, 1e-4 * sx * sx)


class NumpyEkf:
    """The plain EKF of hbn on a model file's dict."""

    def __init__(self, model: Dict[str, Any]) -> None:
        self.tr = NumpyGP(model["transition"])
        self.se = NumpyGP(model["sensor"])
        # Play operators of the input (docs/memory.md): their radii, in the input's units
        # (absent: none).
        self.radii = np.asarray(model.get("play_radii", []), dtype=float)
        # Lags after the plays: first-order low-pass filters of u with coefficients
        # a = 1 - exp(-1 / (rate tau)) (hbn_core::lag_coefficient).
        params = model.get("params", {})
        rate = float(params.get("rate_hz", 100.0))
        self.lag_a = np.array([-math.expm1(-1.0 / (rate * float(tau))) for tau in params.get("lags") or []])
        # The sensor reads [x_{k-1}, y_{k-1}, x_k] (the thesis), [x_{k-1}, x_k] (a sensor of
        # the state only, `sensor_inputs = state`), or [x_k, q^1_k, q^2_k] with plays of the
        # state of these radii (`sensor_inputs = memory`, docs/memory.md).
        self.state_radii = np.asarray(model.get("sensor_memory_radii", []), dtype=float)
        if len(self.state_radii) and self.se.d != 1 + len(self.state_radii):
            raise ValueError("a sensor with memory reads the state and one input per play of it")
        if self.tr.d != 4 + len(self.radii) + len(self.lag_a) or self.se.d not in (2, 3):
            raise ValueError(
                "not an HBN model (transition needs 4 inputs plus one per play and lag, sensor 3 or 2)"
            )
        self.cfg = ekf_config(model)
        self.model = model
        self.state: Optional[Dict[str, Any]] = None

    def _initialise(self, u_k: float, y_k: float) -> Tuple[float, float]:
        c = self.cfg
        u0 = u_k if math.isfinite(u_k) else 0.0
        r = max(c["r_floor"], c["r_scale"] * max(self.se.noise_var_raw, c["r_model_floor"]))
        if math.isfinite(y_k):
            s0, s_var = _clamp(y_k, c["y_bounds"]), r
        else:
            s0, s_var = 0.5 * sum(c["y_bounds"]), c["p_max"]
        v = c["x0_var"]
        p = np.array([[v, v, 0.0], [v, v, 0.0], [0.0, 0.0, s_var]])
        p = _bound_cov(p, c["p_min"], c["p_max"])
        self.state = {
            "z": np.array([c["x0_mean"], c["x0_mean"], s0]),
            "p": p,
            "u_last": u0,
            "u_prev": u0,
            "plays": np.full(len(self.radii) + len(self.lag_a), u0),
            "memory": np.full(len(self.state_radii), c["x0_mean"]),
            "rejected_run": 0,
            "lost_run": 0,
        }
        return c["x0_mean"], c["std_scale"] * math.sqrt(p[0, 0])

    def step(self, u_k: float, y_k: float) -> Tuple[float, float]:
        c = self.cfg
        st = self.state
        if st is None:
            return self._initialise(u_k, y_k)
        if not math.isfinite(u_k):
            u_k = st["u_last"]
        z, p = st["z"], st["p"]
        x1, x2, s1 = z[0], z[1], z[2]
        jm = c["jac_max"]
        r = max(c["r_floor"], c["r_scale"] * max(self.se.noise_var_raw, c["r_model_floor"]))
        t = self._linearise(
            self.tr, np.concatenate([[x1, x2, st["u_last"], st["u_prev"]], st["plays"]])
        )
        left_box = False
        if t is not None:
            left_box = not (c["x_bounds"][0] <= t[0] <= c["x_bounds"][1])
            xk = _clamp(t[0], c["x_bounds"])
            state_only = self.se.d == 2
            sr = self.state_radii
            if len(sr):
                # The plays of the estimates, moved by x_k; those x_k drags pass on its slope.
                held = np.maximum(xk - sr, np.minimum(xk + sr, st["memory"]))
                moving = held != st["memory"]
                s = self._linearise(self.se, np.concatenate([[xk], held]))
            else:
                s = self._linearise(self.se, np.array([x1, xk] if state_only else [x1, s1, xk]))
            if s is not None:
                a1, a2 = _clamp_jac(t[2][0], jm), _clamp_jac(t[2][1], jm)
                # The gradient w.r.t. x_{k-1}, s_{k-1}, x_k (none for s_{k-1} without it).
                if len(sr):
                    grad = [0.0, 0.0, s[2][0] + float(np.sum(s[2][1:] * moving))]
                else:
                    grad = [s[2][0], 0.0, s[2][1]] if state_only else list(s[2])
                cc, e, f = (_clamp_jac(grad[0], jm), _clamp_jac(grad[1], jm), _clamp_jac(grad[2], jm))
                fm = np.array([[a1, a2, 0.0], [1.0, 0.0, 0.0], [cc + f * a1, f * a2, e]])
                g = np.array([1.0, 0.0, f])
                q_x = _floor(
                    c["q_scale"] * max(self.tr.noise_var_raw + t[1], c["qx_model_floor"]),
                    c["q_floor"],
                )
                q_s = _floor(c["q_scale"] * s[1], c["q_floor"])
                s_pred = _clamp(s[0], c["y_bounds"])
                z = np.array([xk, x1, s_pred])
                r = _floor(
                    c["r_scale"] * max(self.se.noise_var_raw, c["r_model_floor"]), c["r_floor"]
                )
            else:
                fm = np.array([[t[2][0], t[2][1], 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
                g = np.array([1.0, 0.0, 0.0])
                q_x = _floor(
                    c["q_scale"] * max(self.tr.noise_var_raw + t[1], c["qx_model_floor"]),
                    c["q_floor"],
                )
                q_s = c["p_max"] * 0.01
                z = np.array([xk, x1, s1])
        else:
            fm = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
            g = np.array([1.0, 0.0, 0.0])
            q_x = q_s = c["p_max"] * 0.01
            z = np.array([x1, x1, s1])
        q = np.outer(g * q_x, g)
        q[2, 2] += q_s
        p = _bound_cov(fm @ p @ fm.T + q, c["p_min"], c["p_max"])
        st["u_prev"], st["u_last"] = st["u_last"], u_k
        # The plays follow u_k at their radius: p = max(u - r, min(u + r, p)); then the lags:
        # p += a (u - p).
        nr = len(self.radii)
        mem = st["plays"].copy()
        mem[:nr] = np.maximum(u_k - self.radii, np.minimum(u_k + self.radii, mem[:nr]))
        mem[nr:] = mem[nr:] + self.lag_a * (u_k - mem[nr:])
        st["plays"] = mem
        # ---- update (Joseph form, H = [0, 0, 1]) ----
        if math.isfinite(y_k):
            s_var = p[2, 2] + r
            innov = y_k - z[2]
            nis = innov * innov / s_var if math.isfinite(s_var) and s_var > 0 else 0.0
            if math.isfinite(s_var) and s_var >= c["innovation_min"]:
                if c["nis_gate"] > 0.0 and nis > c["nis_gate"]:
                    # The outlier gate (hbn_core::ekf::update) down-weights: S becomes
                    # innov^2 / gate and R grows by the same amount.
                    st["rejected_run"] += 1
                    s_gated = innov * innov / c["nis_gate"]
                    r = r + (s_gated - s_var)
                    s_var = s_gated
                else:
                    st["rejected_run"] = 0
                gain = p[:, 2] / s_var
                zn = z + gain * innov
                ikh = np.eye(3)
                ikh[:, 2] -= gain
                pn = ikh @ p @ ikh.T + r * np.outer(gain, gain)
                if np.all(np.isfinite(zn)) and np.all(np.isfinite(pn)):
                    xb, yb = c["x_bounds"], c["y_bounds"]
                    z = np.array([_clamp(zn[0], xb), _clamp(zn[1], xb), _clamp(zn[2], yb)])
                    p = _bound_cov(pn, c["p_min"], c["p_max"])
        # A lost filter (hbn_core's Ekf::relocalise): re-started from the prior of x at y_k.
        st["lost_run"] = st["lost_run"] + 1 if left_box else 0
        if st["lost_run"] >= LOST_AFTER:
            prior = initial_state(self.model, y_k)
            if prior is not None:
                xm, xv = prior
                rr = max(c["r_floor"], c["r_scale"] * max(self.se.noise_var_raw, c["r_model_floor"]))
                xm = _clamp(xm, c["x_bounds"])
                z = np.array([xm, xm, _clamp(y_k, c["y_bounds"])])
                p = _bound_cov(
                    np.array([[xv, xv, 0.0], [xv, xv, 0.0], [0.0, 0.0, rr]]), c["p_min"], c["p_max"]
                )
                st["lost_run"] = 0
                st["rejected_run"] = 0
                st["memory"] = np.full(len(self.state_radii), xm)
        # The sensor's plays of the state advance with the estimate.
        sr = self.state_radii
        st["memory"] = np.maximum(z[0] - sr, np.minimum(z[0] + sr, st["memory"]))
        st["z"], st["p"] = z, p
        return z[0], c["std_scale"] * math.sqrt(max(p[0, 0], 0.0))

    @staticmethod
    def _linearise(gp: NumpyGP, x: np.ndarray):
        if not np.all(np.isfinite(x)):
            return None
        mean, var, grad = gp.predict(x)
        if not (math.isfinite(mean) and math.isfinite(var) and np.all(np.isfinite(grad))):
            return None
        return mean, var, grad


def numpy_estimate(model: Dict[str, Any], u: np.ndarray, y: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Runs the numpy EKF over a sequence: ``(x, x_std)``."""
    ekf = NumpyEkf(model)
    # The prior of x_0 comes from the first measurement (the training prior if it is not finite).
    init = initial_state(model, float(y[0])) if len(y) else None
    if init is not None:
        ekf.cfg["x0_mean"], ekf.cfg["x0_var"] = init
    n = len(u)
    x = np.empty(n)
    xs = np.empty(n)
    for k in range(n):
        x[k], xs[k] = ekf.step(float(u[k]), float(y[k]))
    return x, xs


def load_model_json(path: str) -> Dict[str, Any]:
    """The ``model`` object of an hbn model file (checks the format tag)."""
    with open(path, "r", encoding="utf-8") as fh:
        doc = json.load(fh)
    if doc.get("format") != "hbn-model" or not isinstance(doc.get("version"), int):
        raise ValueError(f"{path}: not an hbn model file")
    return doc["model"]


# ------------------------------------------------------------------------------------------------
# Benchmark
# ------------------------------------------------------------------------------------------------


def compare(
    steps: int = 2000,
    max_points: int = 500,
    system: str = "duhem",
    kernel: str = "matern52",
    train_steps: int = 1000,
    seed: int = 1,
    n_starts: int = 1,
    model_path: Optional[str] = None,
    n_inducing: Optional[int] = None,
) -> Dict[str, float]:
    """Fits (or loads) a model, runs both filters on the same test data, returns timings and the
    largest difference."""
    import hbn

    tmp = None
    if model_path is None:
        train = hbn.simulate(system, train_steps, seed=seed, noise_gain=1.0)
        model = hbn.HysteresisModel.fit(
            train["u"], train["x"], train["y"], kernel=kernel, max_points=max_points,
            n_starts=n_starts, seed=seed, n_inducing=n_inducing,
        )
        tmp = tempfile.TemporaryDirectory()
        model_path = os.path.join(tmp.name, "model.hbn")
        model.save(model_path)
    model = hbn.HysteresisModel.load(model_path)
    test = hbn.simulate(system, steps, seed=seed + 100, noise_gain=1.0)
    model_json = load_model_json(model_path)

    t0 = time.perf_counter()
    est = model.estimate(test["u"], test["y"], mode="ekf")
    t_hbn = time.perf_counter() - t0
    t0 = time.perf_counter()
    x_np, xs_np = numpy_estimate(model_json, test["u"], test["y"])
    t_np = time.perf_counter() - t0
    if tmp is not None:
        tmp.cleanup()
    return {
        "steps": steps,
        "n_transition": int(len(model_json["transition"]["alpha"])),
        "n_sensor": int(len(model_json["sensor"]["alpha"])),
        "us_per_step_numpy": 1e6 * t_np / steps,
        "us_per_step_hbn": 1e6 * t_hbn / steps,
        "ratio": t_np / t_hbn,
        "max_abs_diff_x": float(np.max(np.abs(x_np - est.x))),
        "max_abs_diff_x_std": float(np.max(np.abs(xs_np - est.x_std))),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--steps", type=int, default=2000, help="test samples (default 2000)")
    ap.add_argument("--max-points", type=int, default=500, help="support points per GP (default 500)")
    ap.add_argument("--system", default="duhem", help="simulated system (default duhem)")
    ap.add_argument("--kernel", default="matern52", help="kernel of both GPs (default matern52; hbn's default chooses per GP by evidence)")
    ap.add_argument("--train-steps", type=int, default=1000, help="training samples (default 1000)")
    ap.add_argument("--model", default=None, help="use this model file instead of training one")
    ap.add_argument("--inducing", type=int, default=None, help="sparse GPs with this many inducing points (default: exact)")
    a = ap.parse_args(argv)
    r = compare(
        a.steps, a.max_points, a.system, a.kernel, a.train_steps, model_path=a.model,
        n_inducing=a.inducing,
    )
    kind = "inducing" if a.inducing else "support"
    print(f"model: {r['n_transition']} transition + {r['n_sensor']} sensor {kind} points; {r['steps']} steps")
    print(f"numpy : {r['us_per_step_numpy']:9.1f} us/step")
    print(f"hbn   : {r['us_per_step_hbn']:9.1f} us/step")
    print(f"ratio : {r['ratio']:9.1f} x (numpy time / hbn time)")
    print(f"max |x_numpy - x_hbn|     = {r['max_abs_diff_x']:.3e}")
    print(f"max |std_numpy - std_hbn| = {r['max_abs_diff_x_std']:.3e}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
