"""Tests of the vector GP-EKF (``vector_gp_ekf.py``) and of its runner (``vector_run.py``).

    pytest benches/baselines/test_vector_baselines.py   # HBN_BIN=/path/to/hbn for the runner

Fast: small GPs on toy data. The runner's end-to-end test needs the ``hbn`` CLI and the wheel
(as ``test_baselines.py``'s) and skips, saying so, without them.
"""

from __future__ import annotations

import json
import math
import sys
import warnings
from pathlib import Path
from typing import Dict, List, Tuple

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

import common  # noqa: E402
import gp_ekf  # noqa: E402
import run  # noqa: E402
import vector_gp_ekf as vg  # noqa: E402
import vector_run  # noqa: E402

# ------------------------------------------------------------------------------------------------
# A linear-Gaussian vector system: du = 2, dx = 2, dy = 3
# ------------------------------------------------------------------------------------------------

A = np.array([[0.85, 0.10], [-0.10, 0.80]])
B = np.array([[0.30, 0.05], [0.10, 0.25]])
C = np.array([[1.0, 0.0], [0.0, 1.0], [0.6, -0.4]])
Q_STD, R_STD = 0.03, 0.01


def linear_log(n: int, seed: int) -> vg.VectorLog:
    """``x_k = A x_{k-1} + B u_{k-1} + w_k``, ``y_k = C x_k + v_k`` with random-ramp inputs in
    ``[-1, 1]``; ``w`` and ``v`` white with standard deviations ``Q_STD`` and ``R_STD``."""
    rng = np.random.default_rng(seed)
    u = np.clip(np.cumsum(rng.uniform(-0.15, 0.15, (n, 2)), axis=0), -1.0, 1.0)
    x = np.zeros((n, 2))
    for k in range(1, n):
        x[k] = A @ x[k - 1] + B @ u[k - 1] + Q_STD * rng.standard_normal(2)
    y = x @ C.T + R_STD * rng.standard_normal((n, 3))
    return vg.VectorLog(u=u, x=x, y=y, rate=100.0)


def open_loop(u: np.ndarray, x0: np.ndarray) -> np.ndarray:
    """The true model's prediction of ``x`` from ``u`` and the true ``x_0`` alone (no sensor)."""
    x = np.zeros((len(u), 2))
    x[0] = x0
    for k in range(1, len(u)):
        x[k] = A @ x[k - 1] + B @ u[k - 1]
    return x


@pytest.fixture(scope="module")
def linear_fit() -> Tuple[vg.VectorGpEkfModel, vg.VectorLog]:
    train = [linear_log(500, 1), linear_log(500, 2)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # sklearn's ConvergenceWarning about bounds
        model = vg.fit(train, seed=0, rows=300)
    return model, linear_log(600, 3)


# ------------------------------------------------------------------------------------------------
# Jacobians
# ------------------------------------------------------------------------------------------------


def nonlinear_logs(n: int, count: int) -> List[vg.VectorLog]:
    """A nonlinear toy with du = 2, dx = 2, dy = 3 and enough noise for well-conditioned GPs."""
    out = []
    for i in range(count):
        rng = np.random.default_rng(40 + i)
        u = np.clip(np.cumsum(rng.uniform(-0.2, 0.2, (n, 2)), axis=0), -1.0, 1.0)
        x = np.zeros((n, 2))
        for k in range(1, n):
            x[k] = np.tanh(A @ x[k - 1] + B @ u[k - 1] + 0.5 * x[k - 1] * u[k - 1]) + 0.05 * rng.standard_normal(2)
        y = np.column_stack([np.sin(2 * x[:, 0]) + x[:, 1] ** 2, x[:, 0] * x[:, 1], np.exp(x[:, 1])])
        out.append(vg.VectorLog(u=u, x=x, y=y + 0.05 * rng.standard_normal((n, 3)), rate=100.0))
    return out


def test_jacobian_matches_finite_differences() -> None:
    logs = nonlinear_logs(200, 3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = vg.fit(logs[:2], seed=0, rows=150)
    test = logs[2]
    rng = np.random.default_rng(4)
    for k in (20, 90, 170):
        z = np.concatenate([test.x[k - 1], test.x[k - 2], test.y[k - 1]]) + 0.05 * rng.standard_normal(7)
        u1, u2 = test.u[k - 1], test.u[k - 2]
        z_pred, F, Q = vg.predict_step(model, z, u1, u2)
        assert F.shape == Q.shape == (7, 7)
        h = 1e-5
        fd = np.column_stack(
            [(vg.predict_step(model, z + h * e, u1, u2)[0] - vg.predict_step(model, z - h * e, u1, u2)[0]) / (2 * h) for e in np.eye(7)]
        )
        assert np.allclose(F, fd, rtol=1e-5, atol=1e-7), np.abs(F - fd).max()
        # The sensors read x_k, which reads x_{k-2}: the chained block is there.
        assert np.abs(F[4:, 2:4]).max() > 1e-2
        # x_{k-1} of the new state is x_{k-1} of the old one.
        assert np.array_equal(z_pred[2:4], z[:2])
        assert np.allclose(Q, Q.T) and np.all(np.linalg.eigvalsh(Q) > -1e-12)


def test_process_noise_reaches_the_sensor_states_through_the_sensor_gps() -> None:
    trans = [LinearGP([1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], 0.0, 0.01, 0.02), LinearGP([0.0] * 8, 0.0, 0.03, 0.04)]
    sens = [LinearGP([0.0, 0.0, 0.0, 2.0, -1.0], 0.0, 0.005, 0.1)]
    model = vg.VectorGpEkfModel(trans, sens, np.zeros((3, 1)), np.zeros((3, 2)), np.ones(2))  # type: ignore[arg-type]
    _, _, Q = vg.predict_step(model, np.zeros(5), np.zeros(2), np.zeros(2))
    qx = np.array([0.03, 0.07])  # latent variance + white noise of each transition GP
    G = np.array([[1.0, 0.0], [0.0, 1.0], [0.0, 0.0], [0.0, 0.0], [2.0, -1.0]])
    expected = G @ np.diag(qx) @ G.T
    expected[4, 4] += 0.005  # the sensor GP's latent variance (its white noise is R)
    assert np.allclose(Q, expected, rtol=0, atol=1e-15)


# ------------------------------------------------------------------------------------------------
# Linear stand-ins: the EKF is exact Gaussian filtering
# ------------------------------------------------------------------------------------------------


class LinearGP:
    """A stand-in for SkGP: a linear mean with a constant latent variance and noise."""

    def __init__(self, w: List[float], b: float, var: float, noise: float) -> None:
        self.w, self.b, self.var, self.noise_var = np.array(w, dtype=np.float64), b, var, noise

    def predict(self, x: np.ndarray) -> Tuple[float, float, np.ndarray]:
        return float(self.w @ x + self.b), self.var, self.w.copy()


def test_ekf_equals_exact_gaussian_filtering_on_a_linear_vector_model() -> None:
    """With linear 'GPs' the augmented model is linear-Gaussian, so the EKF must give the exact
    filtering posterior p(x_k | y_1..y_k) (a sensor's missing sample conditions on nothing),
    computed here by conditioning the joint Gaussian of all variables, each written as a mean
    plus coefficients on independent standard normals."""
    du, dx, dy = 2, 2, 2
    rng = np.random.default_rng(11)
    A1, A2 = np.array([[0.6, 0.1], [-0.2, 0.5]]), np.array([[0.2, 0.0], [0.05, 0.1]])
    B1, B2, b = rng.uniform(-0.5, 0.5, (dx, du)), rng.uniform(-0.2, 0.2, (dx, du)), np.array([0.05, -0.03])
    Cs, Es, Fs, bs = rng.uniform(-0.4, 0.4, (dy, dx)), np.array([0.3, 0.5]), rng.uniform(-1, 1, (dy, dx)), np.array([0.01, -0.02])
    qlat, qnoise, qs, r = np.array([0.01, 0.02]), np.array([0.02, 0.01]), np.array([0.005, 0.002]), np.array([0.03, 0.01])
    trans = [LinearGP(list(np.concatenate([A1[i], A2[i], B1[i], B2[i]])), b[i], qlat[i], qnoise[i]) for i in range(dx)]
    sens = [LinearGP(list(np.concatenate([Cs[j], [Es[j]], Fs[j]])), bs[j], qs[j], r[j]) for j in range(dy)]
    init_y, init_x = rng.uniform(0, 1, (120, dy)), rng.uniform(0, 1, (120, dx))
    model = vg.VectorGpEkfModel(trans, sens, init_y, init_x, np.ones(dx))  # type: ignore[arg-type]
    n = 6
    u = rng.uniform(0, 1, (n, du))
    y = rng.uniform(0, 1, (n, dy))
    y[3, 1] = np.nan  # sensor 1 sits step 3 out
    x_hat, x_std = vg.estimate(model, u, y)
    m0, C0 = vg.initial_x(model, y[0])

    # Independent standard normals: x_0 (dx), s_0 (dy), then per step w (dx), ws (dy), v (dy).
    per = dx + 2 * dy
    dim = dx + dy + per * (n - 1)
    L0 = np.linalg.cholesky(C0)
    x_mean, x_coef = [m0], [np.zeros((dx, dim))]
    x_coef[0][:, :dx] = L0
    s_mean, s_coef = [y[0].copy()], [np.zeros((dy, dim))]
    s_coef[0][:, dx : dx + dy] = np.diag(np.sqrt(r))
    obs_mean: List[float] = []
    obs_coef: List[np.ndarray] = []
    obs_val: List[float] = []
    for k in range(1, n):
        off = dx + dy + per * (k - 1)
        u2 = u[k - 2] if k >= 2 else u[0]
        xm2, xc2 = (x_mean[k - 2], x_coef[k - 2]) if k >= 2 else (x_mean[0], x_coef[0])
        mk = A1 @ x_mean[k - 1] + A2 @ xm2 + B1 @ u[k - 1] + B2 @ u2 + b
        ck = A1 @ x_coef[k - 1] + A2 @ xc2
        ck[:, off : off + dx] += np.diag(np.sqrt(qlat + qnoise))
        x_mean.append(mk)
        x_coef.append(ck)
        sm = Cs @ x_mean[k - 1] + Es * s_mean[k - 1] + Fs @ mk + bs
        sc = Cs @ x_coef[k - 1] + Es[:, None] * s_coef[k - 1] + Fs @ ck
        sc[:, off + dx : off + dx + dy] += np.diag(np.sqrt(qs))
        s_mean.append(sm)
        s_coef.append(sc)
        for j in range(dy):
            if np.isfinite(y[k, j]):
                g = sc[j].copy()
                g[off + dx + dy + j] += math.sqrt(r[j])
                obs_mean.append(sm[j])
                obs_coef.append(g)
                obs_val.append(y[k, j])
        Y = np.array(obs_coef)
        Syy = Y @ Y.T
        Sxy = x_coef[k] @ Y.T
        gain = np.linalg.solve(Syy, Sxy.T).T
        mean = x_mean[k] + gain @ (np.array(obs_val) - np.array(obs_mean))
        cov = x_coef[k] @ x_coef[k].T - gain @ Sxy.T
        assert np.allclose(x_hat[k], mean, rtol=0, atol=1e-10), k
        assert np.allclose(x_std[k], np.sqrt(np.diag(cov)), rtol=0, atol=1e-10), k
    assert np.array_equal(x_hat[0], m0) and np.allclose(x_std[0], np.sqrt(np.diag(C0)))


# ------------------------------------------------------------------------------------------------
# One dimension: the scalar baseline, step for step
# ------------------------------------------------------------------------------------------------


def _scalar_logs() -> List[common.Log]:
    out = []
    for i in range(3):
        rng = np.random.default_rng(20 + i)
        u = np.clip(np.cumsum(rng.uniform(-0.1, 0.1, 220)), -1, 1)
        x = np.zeros(220)
        for k in range(1, 220):
            x[k] = 0.8 * x[k - 1] + 0.3 * np.tanh(2 * u[k - 1]) + 0.02 * rng.standard_normal()
        y = x + 0.3 * x**2 + 0.01 * rng.standard_normal(220)
        out.append(common.Log(u=u, x=x, y=y, rate=100.0))
    return out


def test_one_dimension_is_the_scalar_baseline() -> None:
    logs = _scalar_logs()
    train, test = logs[:2], logs[2]
    vlogs = [vg.VectorLog(u=lg.u[:, None], x=lg.x[:, None], y=lg.y[:, None], rate=lg.rate) for lg in logs]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scalar = gp_ekf.fit(train, seed=3, rows=150)
        vector = vg.fit(vlogs[:2], seed=3, rows=150)
    # Same rows, same seeds: the same GPs.
    assert np.array_equal(vector.transition[0].X, scalar.transition.X)
    assert np.array_equal(vector.sensor[0].X, scalar.sensor.X)
    u, y = test.u.copy(), test.y.copy()
    u[40], y[60], y[61] = np.nan, np.nan, np.inf
    xs, ss = gp_ekf.estimate(scalar, u, y)
    xv, sv = vg.estimate(vector, u[:, None], y[:, None])
    assert xv.shape == sv.shape == (220, 1)
    assert np.allclose(xv[:, 0], xs, rtol=0, atol=1e-10)
    assert np.allclose(sv[:, 0], ss, rtol=0, atol=1e-10)


# ------------------------------------------------------------------------------------------------
# Tracking the linear-Gaussian system with fitted GPs
# ------------------------------------------------------------------------------------------------

#: The 2-sigma coverage the GP-EKF reaches on the linear system (0.94-0.96 for GP seeds 0 and
#: 5): the Gaussian 0.954 within the spread of 600 correlated samples and of 300-row GPs'
#: variances. The nRMSE is 0.16-0.19 of the open loop's.
COVERAGE_BAND = (0.85, 0.995)


def test_tracks_a_linear_gaussian_system(linear_fit: Tuple[vg.VectorGpEkfModel, vg.VectorLog]) -> None:
    model, test = linear_fit
    assert (model.dx, model.dy) == (2, 3) and model.transition[0].X.shape[1] == 8
    x, s = vg.estimate(model, test.u, test.y)
    ol = open_loop(test.u, test.x[0])
    for i in range(2):
        ekf = common.score(x[:, i], s[:, i], test.x[:, i])
        base = common.nrmse(ol[:, i], test.x[:, i])
        assert ekf["nrmse"] < 0.4 * base, (i, ekf["nrmse"], base)
        assert COVERAGE_BAND[0] <= ekf["coverage_2sigma"] <= COVERAGE_BAND[1], (i, ekf)
        assert ekf["samples"] == len(test)


def test_missing_measurements_do_not_produce_nan(linear_fit: Tuple[vg.VectorGpEkfModel, vg.VectorLog]) -> None:
    model, test = linear_fit
    y, u = test.y.copy(), test.u.copy()
    y[100, 1] = np.nan  # one sensor out
    y[200:205] = np.nan  # every sensor out for 5 steps
    y[300, 2] = np.inf
    y[0, 0] = np.nan  # no first sample: the first finite one stands in
    u[150, 0] = np.nan  # a missing input holds the last one
    x, s = vg.estimate(model, u, y)
    assert np.all(np.isfinite(x)) and np.all(np.isfinite(s)) and np.all(s > 0)
    assert np.all(s[204] > s[199])  # no update for 5 steps: the uncertainty grows
    ref, _ = vg.estimate(model, test.u, test.y)
    assert np.allclose(x[:100], ref[:100], rtol=0, atol=0.05)  # the missing y_0 entry is not fatal


def test_update_skips_non_finite_sensors_only() -> None:
    trans = [LinearGP([0.5, 0, 0, 0, 0, 0, 0, 0], 0.0, 0.01, 0.01), LinearGP([0, 0.5, 0, 0, 0, 0, 0, 0], 0.0, 0.01, 0.01)]
    sens = [LinearGP([0, 0, 0, 1.0, 0], 0.0, 1e-3, 1e-2), LinearGP([0, 0, 0, 0, 1.0], 0.0, 1e-3, 1e-2)]
    model = vg.VectorGpEkfModel(trans, sens, np.zeros((3, 2)), np.zeros((3, 2)), np.ones(2))  # type: ignore[arg-type]
    z, P = np.zeros(6), np.eye(6) * 0.1
    z1, P1, read = vg.update_step(model, z, P, np.array([1.0, np.nan]))
    assert read == 1 and z1[4] > 0.5 and z1[5] == 0.0 and P1[5, 5] == pytest.approx(0.1)
    _, P2, read = vg.update_step(model, z, P, np.array([np.nan, np.nan]))
    assert read == 0 and np.array_equal(P2, P)


def test_initial_state_from_the_nearest_training_measurements() -> None:
    init_y = np.column_stack([np.arange(200.0), 100.0 * np.arange(200.0)])
    init_x = np.column_stack([np.where(init_y[:, 0] < 100, 0.0, 1.0) + 0.001 * init_y[:, 0], np.zeros(200)])
    model = vg.VectorGpEkfModel([None, None], [None, None], init_y, init_x, np.array([1.2, 3.0]))  # type: ignore[list-item]
    m, C = vg.initial_x(model, np.array([160.2, 16020.0]))
    near = init_x[136:186]  # the 50 samples nearest (each sensor scaled by its std)
    assert np.allclose(m, near.mean(axis=0))
    assert C[0, 0] == pytest.approx(near[:, 0].var())
    assert C[1, 1] == pytest.approx(1e-4 * 3.0**2)  # a constant component gets the floor
    # A missing sensor is left out of the distance.
    m2, _ = vg.initial_x(model, np.array([np.nan, 16020.0]))
    assert np.allclose(m2, m)


def test_training_rows_never_straddle_two_logs() -> None:
    def lg(base: float, n: int) -> vg.VectorLog:
        k = np.arange(n, dtype=np.float64)[:, None]
        return vg.VectorLog(u=base + k + [0.0, 0.5], x=base + 10 + k + [0.0, 0.25], y=base + 20 + k + [0.0, 0.1, 0.2], rate=1.0)

    a, b = lg(0.0, 4), lg(100.0, 3)
    X, t = vg.transition_rows([a, b])
    assert X.shape == (3, 8) and t.shape == (3, 2)
    assert X[0].tolist() == [11, 11.25, 10, 10.25, 1, 1.5, 0, 0.5] and t[0].tolist() == [12, 12.25]
    assert X[2].tolist() == [111, 111.25, 110, 110.25, 101, 101.5, 100, 100.5]
    Xs, ts = vg.sensor_rows([a, b], 2)
    assert Xs.shape == (3, 5) and Xs[0].tolist() == [11, 11.25, 21.2, 12, 12.25] and ts.tolist() == [22.2, 23.2, 122.2]


# ------------------------------------------------------------------------------------------------
# The runner, end to end on logs written by the hbn CLI
# ------------------------------------------------------------------------------------------------


def test_log_seeds_are_the_vector_eval_protocol() -> None:
    assert vector_run.log_seeds(3) == {"train": 3, "test": 1003}


def test_runner_end_to_end(tmp_path: Path) -> None:
    pytest.importorskip("hbn")
    try:
        run.hbn_bin()
    except FileNotFoundError as e:
        pytest.skip(str(e))
    doc = vector_run.grid(["finger"], [1.0], [1], tmp_path, steps=300, test_steps=200, gp_rows=80, keep_logs=True, command="test")
    saved: Dict = json.loads((tmp_path / "vector_grid.json").read_text())
    assert saved["runs"] == json.loads(json.dumps(doc["runs"]))
    (cell,) = saved["runs"]
    assert cell["dims"] == {"du": 2, "dx": 2, "dy": 3} and cell["n_test"] == 200
    for m in ("hbn", "gp_ekf"):
        assert "error" not in cell[m], cell[m]
        assert len(cell[m]["components"]) == 2 and cell[m]["train_seconds"] > 0
        for c in cell[m]["components"]:
            assert c["samples"] == 200 and 0 < c["nrmse"] < 0.5 and c["coverage_2sigma"] is not None
    h, g = cell["hbn"]["components"], cell["gp_ekf"]["components"]
    assert cell["ratio_nrmse"] == pytest.approx([h[i]["nrmse"] / g[i]["nrmse"] for i in range(2)])
    # Scored on the test log (seed 1001), never on the training log (seed 1).
    test_log = tmp_path / "logs" / "finger-g1-s1" / "test.mcap"
    _, test = vg.read_vector_logs([str(tmp_path / "logs" / "finger-g1-s1" / "train.mcap")], str(test_log))
    _, x, s = vector_run.read_estimate_csv(tmp_path / "logs" / "finger-g1-s1" / "estimate.csv", 2)
    assert h[0]["nrmse"] == pytest.approx(common.nrmse(x[:, 0], test.x[:, 0]))
    md = (tmp_path / "vector_grid.md").read_text()
    assert "- command: `test`" in md and "| finger | 1 | 1 |" in md and "hbn / GP-EKF" in md
