"""Tests of the baselines (fast: tiny logs, one system; the LSTM tests skip without torch).

    pytest benches/baselines          # HBN_BIN=/path/to/hbn for the end-to-end tests

The end-to-end tests need the ``hbn`` CLI (``$HBN_BIN``, ``target/release/hbn`` or ``hbn`` on
the PATH) to write MCAP logs; they skip, saying so, when there is none.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Dict, List, Tuple

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

import common  # noqa: E402
import gp_ekf  # noqa: E402
import lstm  # noqa: E402
import narx  # noqa: E402
import run  # noqa: E402

# ------------------------------------------------------------------------------------------------
# Metrics on hand-made cases
# ------------------------------------------------------------------------------------------------


def test_perfect_estimate_with_unit_std_is_fully_covered() -> None:
    x = np.linspace(-1.0, 2.0, 50)
    c = common.calibration(x, np.ones_like(x), x)
    assert c["coverage_1sigma"] == 1.0 and c["coverage_2sigma"] == 1.0
    assert c["mean_nees"] == 0.0
    assert c["nlpd"] == pytest.approx(0.5 * math.log(2.0 * math.pi), abs=1e-15)
    assert c["samples"] == 50


def test_errors_equal_to_the_std_give_nees_one() -> None:
    rng = np.random.default_rng(0)
    std = rng.uniform(0.1, 3.0, 40)
    sign = np.where(rng.random(40) < 0.5, -1.0, 1.0)
    ref = rng.normal(size=40)
    c = common.calibration(ref + sign * std, std, ref)
    assert c["mean_nees"] == pytest.approx(1.0, abs=1e-12)
    assert c["coverage_2sigma"] == 1.0
    # NLPD of z = 1: ln(2 pi s^2) / 2 + 1/2, averaged.
    assert c["nlpd"] == pytest.approx(np.mean(0.5 * np.log(2 * np.pi * std**2) + 0.5), abs=1e-12)
    # Exactly one standard deviation off (exact in binary floating point) counts as covered.
    r4, s4 = np.array([0.0, 1.0, 2.0, 3.0]), np.array([0.5, 1.0, 2.0, 4.0])
    exact = common.calibration(r4 + np.array([1.0, -1.0, 1.0, -1.0]) * s4, s4, r4)
    assert exact["coverage_1sigma"] == 1.0 and exact["mean_nees"] == 1.0


def test_calibration_counts_and_skips_unscorable_samples() -> None:
    # Errors of 0.5, 1.5 and 3 standard deviations (std 2), plus a NaN and a zero std (the same
    # case as hbn_model::metrics' unit test).
    est = np.array([0.0, 0.0, 0.0, np.nan, 0.0])
    std = np.array([2.0, 2.0, 2.0, 1.0, 0.0])
    ref = np.array([1.0, -3.0, 6.0, 0.0, 0.0])
    c = common.calibration(est, std, ref)
    assert c["samples"] == 3
    assert c["coverage_1sigma"] == pytest.approx(1 / 3)
    assert c["coverage_2sigma"] == pytest.approx(2 / 3)
    assert c["mean_nees"] == pytest.approx((0.25 + 2.25 + 9.0) / 3)
    nothing = common.calibration(np.array([np.nan]), np.array([1.0]), np.array([0.0]))
    assert nothing["samples"] == 0 and math.isnan(nothing["mean_nees"])


def test_rmse_and_nrmse_known_values() -> None:
    assert common.rmse(np.array([1.0, 2.0]), np.array([1.0, 4.0])) == pytest.approx(math.sqrt(2))
    assert common.nrmse(np.array([1.0, 2.0]), np.array([1.0, 4.0])) == pytest.approx(math.sqrt(2) / 3)
    assert math.isnan(common.nrmse(np.array([1.0]), np.array([1.0])))
    # A NaN estimate is left out of the RMSE.
    assert common.rmse(np.array([np.nan, 3.0]), np.array([0.0, 1.0])) == pytest.approx(2.0)


def test_point_estimate_has_null_calibration() -> None:
    s = common.score(np.array([0.0, 1.0]), None, np.array([0.0, 2.0]))
    assert s["rmse"] == pytest.approx(math.sqrt(0.5))
    for k in ("coverage_1sigma", "coverage_2sigma", "mean_nees", "nlpd"):
        assert s[k] is None
    assert s["samples"] == 2


def test_metrics_match_hbn_score_when_the_wheel_has_it() -> None:
    hbn = pytest.importorskip("hbn")
    if not hasattr(hbn._hbn, "score"):
        pytest.skip("this hbn wheel predates Estimate.score")
    rng = np.random.default_rng(3)
    ref = rng.normal(size=300)
    std = rng.uniform(0.2, 2.0, 300)
    est = ref + std * rng.normal(size=300)
    ours, theirs = common.score(est, std, ref), dict(hbn._hbn.score(est, std, ref))
    for k in ("rmse", "nrmse", "coverage_1sigma", "coverage_2sigma", "mean_nees", "nlpd", "samples"):
        assert ours[k] == pytest.approx(theirs[k], rel=1e-12), k


# ------------------------------------------------------------------------------------------------
# Training sets
# ------------------------------------------------------------------------------------------------


def _log(u: List[float], x: List[float], y: List[float]) -> common.Log:
    return common.Log(np.array(u, float), np.array(x, float), np.array(y, float), rate=100.0)


def test_training_rows_never_straddle_two_logs() -> None:
    a = _log([0, 1, 2, 3], [10, 11, 12, 13], [20, 21, 22, 23])
    b = _log([100, 101, 102], [110, 111, 112], [120, 121, 122])
    Xd, td = common.transition_rows([a, b])
    assert Xd.tolist() == [[11, 10, 1, 0], [12, 11, 2, 1], [111, 110, 101, 100]]
    assert td.tolist() == [12, 13, 112]
    Xs, ts = common.sensor_rows([a, b])
    assert Xs.tolist() == [[11, 21, 12], [12, 22, 13], [111, 121, 112]]
    assert ts.tolist() == [22, 23, 122]


def test_subsample_is_seeded_and_drops_non_finite_rows() -> None:
    X = np.arange(200.0).reshape(100, 2)
    t = np.arange(100.0)
    t[5] = np.nan
    a = common.subsample(X, t, 10, np.random.default_rng(7))
    b = common.subsample(X, t, 10, np.random.default_rng(7))
    assert np.array_equal(a[0], b[0]) and a[0].shape == (10, 2)
    assert 5.0 not in a[1]
    assert common.subsample(X, t, 1000, np.random.default_rng(0))[0].shape == (99, 2)


# ------------------------------------------------------------------------------------------------
# scikit-learn GP and the EKF
# ------------------------------------------------------------------------------------------------


def test_gp_prediction_matches_sklearn_and_its_gradient_finite_differences() -> None:
    rng = np.random.default_rng(1)
    X = rng.uniform(0, 1, (80, 3))
    t = np.sin(3 * X[:, 0]) + X[:, 1] * X[:, 2] + 0.01 * rng.normal(size=80)
    gp = gp_ekf.SkGP(seed=0).fit(X, t)
    Xq = rng.uniform(0, 1, (5, 3))
    mu, sd = gp.gpr.predict(Xq, return_std=True)
    for i in range(5):
        m, v, g = gp.predict(Xq[i])
        assert m == pytest.approx(mu[i], abs=1e-9)
        # scikit-learn's std includes the white noise; ours is the latent variance.
        assert v + gp.noise_var == pytest.approx(sd[i] ** 2, rel=1e-6)
        h = 1e-5
        fd = [(gp.predict(Xq[i] + h * e)[0] - gp.predict(Xq[i] - h * e)[0]) / (2 * h) for e in np.eye(3)]
        assert np.allclose(g, fd, rtol=1e-5, atol=1e-6)


class LinearGP:
    """A stand-in for SkGP: a linear mean with a constant latent variance and noise."""

    def __init__(self, w: List[float], b: float, var: float, noise: float) -> None:
        self.w, self.b, self.var, self.noise_var = np.array(w), b, var, noise

    def predict(self, x: np.ndarray) -> Tuple[float, float, np.ndarray]:
        return float(self.w @ x + self.b), self.var, self.w.copy()


def test_ekf_equals_exact_gaussian_filtering_on_a_linear_model() -> None:
    """With linear 'GPs' the augmented model is linear-Gaussian, so the EKF must give the exact
    filtering posterior p(x_k | y_1..y_k) (same timing: x_k has used y_k), computed here by
    brute-force conditioning of the joint Gaussian of all variables."""
    a1, a2, b1, b2, c, e, f = 0.7, 0.2, 0.5, -0.1, 0.3, 0.4, 0.8
    qx_lat, qx_noise, qs, r = 0.01, 0.02, 0.005, 0.03
    trans = LinearGP([a1, a2, b1, b2], 0.05, qx_lat, qx_noise)
    sens = LinearGP([c, e, f], -0.02, qs, r)
    rng = np.random.default_rng(5)
    init_y, init_x = np.linspace(0, 1, 120), rng.uniform(0, 1, 120)
    model = gp_ekf.GpEkfModel(trans, sens, init_y, init_x, 1.0)  # type: ignore[arg-type]
    n = 7
    u = rng.uniform(0, 1, n)
    y = rng.uniform(0, 1, n)
    x_hat, x_std = gp_ekf.estimate(model, u, y)
    m0, v0 = gp_ekf.initial_x(model, y[0])

    # Every variable as mean + coefficients on independent standard normals:
    # xi = [eps_x0, eps_s0, w_1..w_n-1, ws_1..ws_n-1, v_1..v_n-1].
    dim = 2 + 3 * (n - 1)
    qx = qx_lat + qx_noise

    def var(mean: float, coef: Dict[int, float]) -> Tuple[float, np.ndarray]:
        g = np.zeros(dim)
        for i, val in coef.items():
            g[i] = val
        return mean, g

    xs = [var(m0, {0: math.sqrt(v0)})]
    x_prev2 = xs[0]  # x_{-1} = x_0 (fully correlated prior)
    ss = [var(y[0], {1: math.sqrt(r)})]
    ys: List[Tuple[float, np.ndarray]] = []
    for k in range(1, n):
        u2 = u[k - 2] if k >= 2 else u[0]
        xm1, xm2 = xs[k - 1], (xs[k - 2] if k >= 2 else x_prev2)
        mk = a1 * xm1[0] + a2 * xm2[0] + b1 * u[k - 1] + b2 * u2 + 0.05
        gk = a1 * xm1[1] + a2 * xm2[1]
        gk = gk.copy()
        gk[2 + (k - 1)] += math.sqrt(qx)
        xs.append((mk, gk))
        sm = c * xm1[0] + e * ss[k - 1][0] + f * mk - 0.02
        sg = c * xm1[1] + e * ss[k - 1][1] + f * gk
        sg = sg.copy()
        sg[2 + (n - 1) + (k - 1)] += math.sqrt(qs)
        ss.append((sm, sg))
        yg = sg.copy()
        yg[2 + 2 * (n - 1) + (k - 1)] += math.sqrt(r)
        ys.append((sm, yg))
    for k in range(1, n):
        Y = np.array([g for _, g in ys[:k]])
        ym = np.array([m for m, _ in ys[:k]])
        Syy = Y @ Y.T
        Sxy = xs[k][1] @ Y.T
        gain = np.linalg.solve(Syy, Sxy)
        mean = xs[k][0] + gain @ (y[1 : k + 1] - ym)
        variance = xs[k][1] @ xs[k][1] - Sxy @ gain
        assert x_hat[k] == pytest.approx(mean, abs=1e-10), k
        assert x_std[k] == pytest.approx(math.sqrt(variance), abs=1e-10), k
    assert x_hat[0] == m0 and x_std[0] == pytest.approx(math.sqrt(v0))


def test_ekf_survives_missing_samples() -> None:
    model = gp_ekf.GpEkfModel(
        LinearGP([0.9, 0.0, 0.1, 0.0], 0.0, 1e-3, 1e-3),  # type: ignore[arg-type]
        LinearGP([0.0, 0.5, 0.5], 0.0, 1e-3, 1e-2),  # type: ignore[arg-type]
        np.linspace(0, 1, 60), np.linspace(0, 1, 60), 1.0,
    )  # fmt: skip
    u = np.full(30, 0.5)
    y = np.full(30, 0.5)
    u[10], y[12], y[13] = np.nan, np.nan, np.inf
    x, s = gp_ekf.estimate(model, u, y)
    assert np.all(np.isfinite(x)) and np.all(s > 0)
    assert s[13] > s[11]  # no update: the uncertainty grows


def test_initial_x_from_the_nearest_training_measurements() -> None:
    init_y = np.arange(200.0)
    init_x = np.where(init_y < 100, 0.0, 1.0) + 0.001 * init_y
    model = gp_ekf.GpEkfModel(None, None, init_y, init_x, 1.2)  # type: ignore[arg-type]
    m, v = gp_ekf.initial_x(model, 160.2)
    near = init_x[136:186]  # the 50 y values nearest 160.2
    assert m == pytest.approx(near.mean()) and v == pytest.approx(max(near.var(), 1e-4 * 1.2**2))


# ------------------------------------------------------------------------------------------------
# LSTM
# ------------------------------------------------------------------------------------------------

TINY_LSTM = lstm.LstmConfig(hidden=8, window=32, burn_in=8, batch=8, max_steps=20, eval_every=10)


def _toy_logs(n: int = 160, logs: int = 2) -> List[common.Log]:
    out = []
    for i in range(logs + 1):
        rng = np.random.default_rng(i)
        u = np.cumsum(rng.uniform(-0.05, 0.05, n))
        x = np.convolve(u, np.ones(5) / 5, mode="full")[:n]
        out.append(common.Log(u, x, 2 * x + 0.01 * rng.normal(size=n), rate=100.0))
    return out


def test_lstm_is_causal_and_deterministic() -> None:
    pytest.importorskip("torch")
    *train, test = _toy_logs()
    a = lstm.run(train, test, seed=3, config=TINY_LSTM)
    b = lstm.run(train, test, seed=3, config=TINY_LSTM)
    assert np.array_equal(a["x"], b["x"]) and a["x_std"] is None
    k0 = 90
    y2 = test.y.copy()
    y2[k0:] += 5.0
    c = lstm.run(train, common.Log(test.u, test.x, y2, test.rate), seed=3, config=TINY_LSTM)
    assert np.array_equal(a["x"][:k0], c["x"][:k0])  # the future does not change the past
    assert not np.allclose(a["x"][k0:], c["x"][k0:])
    assert a["steps"] <= TINY_LSTM.max_steps and a["val_history"]


def test_lstm_validation_is_the_tail_of_each_training_log() -> None:
    logs = _toy_logs(100, 2)[:2]
    train, val = lstm._split(logs, 0.2)
    assert [len(f) for f, _ in train] == [80, 80]
    assert [off for off, _, _ in val] == [80, 80]


# ------------------------------------------------------------------------------------------------
# NARX
# ------------------------------------------------------------------------------------------------

TINY_NARX = narx.NarxConfig(windows=(2, 6), widths=(4, 8), max_iter=100)


def test_narx_is_causal_deterministic_and_beats_a_trivial_predictor() -> None:
    *train, test = _toy_logs(200, 2)
    a = narx.run(train, test, seed=3, config=TINY_NARX)
    b = narx.run(train, test, seed=3, config=TINY_NARX)
    assert np.array_equal(a["x"], b["x"]) and a["x_std"] is None
    assert len(a["holdout_mse"]) == 4 and a["window"] in (2, 6) and a["width"] in (4, 8)
    # The chosen candidate is the one with the lowest held-out MSE.
    assert a["holdout_mse"][f"W={a['window']},width={a['width']}"] == min(a["holdout_mse"].values())
    k0 = 120
    u2, y2 = test.u.copy(), test.y.copy()
    u2[k0:] += 3.0
    y2[k0:] -= 5.0
    c = narx.run(train, common.Log(u2, test.x, y2, test.rate), seed=3, config=TINY_NARX)
    assert np.array_equal(a["x"][:k0], c["x"][:k0])  # the future does not change the past
    assert not np.allclose(a["x"][k0:], c["x"][k0:])
    # Better than the trivial predictor: the training mean of x.
    mean_x = np.concatenate([lg.x for lg in train]).mean()
    trivial = common.rmse(np.full_like(test.x, mean_x), test.x)
    assert common.rmse(a["x"], test.x) < 0.5 * trivial


def test_narx_windows_are_causal_and_padded_with_the_first_sample() -> None:
    lg = _log([1, 2, 3, 4], [0, 0, 0, 0], [10, 20, 30, 40])
    sc = narx._Scaler([lg])
    f = sc.windows(lg, 3)
    zu = (np.array([1, 2, 3, 4.0]) - 2.5) / np.std([1, 2, 3, 4.0])
    assert f.shape == (4, 6)
    assert f[0, :3] == pytest.approx([zu[0]] * 3) and f[3, :3] == pytest.approx(zu[1:])
    assert f[2, 3:] == pytest.approx(zu[:3])  # y is a multiple of u here: same standardised values


# ------------------------------------------------------------------------------------------------
# The runner, end to end on logs written by the hbn CLI
# ------------------------------------------------------------------------------------------------


def _hbn_or_skip() -> str:
    pytest.importorskip("hbn")
    try:
        return run.hbn_bin()
    except FileNotFoundError as e:
        pytest.skip(str(e))


@pytest.fixture(scope="module")
def tiny_logs(tmp_path_factory: pytest.TempPathFactory) -> Tuple[List[str], str]:
    _hbn_or_skip()
    wd = tmp_path_factory.mktemp("logs")
    return run.simulate_logs("duhem", 1.0, 1, wd, steps=150)


def test_protocol_seeds_follow_the_readme_example() -> None:
    p = run.protocol_seeds(1)
    assert p["train"] == [(1, 11), (1, 12), (1, 13)] and p["test"] == (2, 21)
    q = run.protocol_seeds(4)
    assert q["test"][0] != q["train"][0][0]
    assert len({s for _, s in q["train"]} | {q["test"][1]}) == 4


def test_runner_end_to_end_on_simulated_logs(
    tiny_logs: Tuple[List[str], str], tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    train, test = tiny_logs
    out = tmp_path / "r.json"
    args = ["--gp-rows", "80", "--lstm-steps", "20", "--json", str(out), "--seed", "1", "--test", test]
    assert run.main(sum((["--train", p] for p in train), []) + args) == 0
    rep = json.loads(out.read_text())
    assert rep["rate"] == 100.0 and rep["n_test"] == 150 and rep["n_train"] == [150] * 3
    ms = rep["methods"]
    for name in ("hbn", "hbn-ekf", "hbn-ekf-blr", "sk-gp-ekf"):
        m = ms[name]
        assert "error" not in m, m
        assert 0.0 < m["nrmse"] < 0.5, (name, m["nrmse"])
        assert 0.0 <= m["coverage_1sigma"] <= m["coverage_2sigma"] <= 1.0
        assert m["mean_nees"] > 0 and m["samples"] == 150
        assert m["train_seconds"] > 0 and m["estimate_seconds"] > 0
        if name.startswith("hbn"):
            assert m["model_rate"] == rep["rate"]  # hbn is trained at the logs' rate
    # The default mode is one the held-out data may choose; an EKF or EKF+BLR default gives
    # exactly that mode's estimate (the runner has no separate UKF method).
    assert ms["hbn"]["mode"] in ("ekf", "ekf-blr", "ukf")
    if ms["hbn"]["mode"] != "ukf":
        assert ms["hbn"]["nrmse"] == ms["hbn-" + ms["hbn"]["mode"]]["nrmse"]
    # The held-out scores training chose by: the default mode's, and the chosen candidate's
    # are the same numbers (the rule picks a candidate by its default mode's scores).
    held = ms["hbn"]["held_out"]
    assert held["mode"] == ms["hbn"]["mode"] and 0.0 < held["nrmse"] < 1.0
    assert math.isfinite(held["nlpd"]) and 0.0 <= held["coverage_2sigma"] <= 1.0
    chosen = [c for c in held["candidates"] if c["chosen"]]
    if held["candidates"]:
        assert len(chosen) == 1 and chosen[0]["config"] == ms["hbn"]["config"]
        assert (chosen[0]["mode"], chosen[0]["nlpd"]) == (held["mode"], held["nlpd"])
    # The open loop of the same fit: a point estimate from u alone, less accurate than the filter.
    ol = ms["hbn-open-loop"]
    assert ol["mode"] == "open-loop" and ol["mean_nees"] is None and ol["samples"] == 150
    assert math.isfinite(ol["nrmse"]) and ol["nrmse"] != ms["hbn-ekf"]["nrmse"]
    printed = capsys.readouterr()
    if lstm.available():
        assert ms["lstm"]["coverage_1sigma"] is None and ms["lstm"]["mean_nees"] is None
        assert math.isfinite(ms["lstm"]["nrmse"])
    else:
        assert "lstm" not in ms
        assert lstm.SKIP_NOTICE in rep["notices"]
        assert lstm.SKIP_NOTICE in printed.err
    assert "sk-gp-ekf" in printed.out
    nx = ms["narx"]
    assert nx["coverage_1sigma"] is None and nx["mean_nees"] is None and nx["nlpd"] is None
    assert 0.0 < nx["nrmse"] < 0.5 and nx["window"] in narx.NarxConfig().windows
    assert "narx" in printed.out


def test_runner_skips_the_lstm_with_a_notice_without_torch(
    tiny_logs: Tuple[List[str], str], monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture
) -> None:
    monkeypatch.setattr(lstm, "available", lambda: False)
    train, test = tiny_logs
    rep = run.evaluate(train, test, methods=["sk-gp-ekf", "lstm"], gp_rows=60)
    assert list(rep["methods"]) == ["sk-gp-ekf"]
    assert rep["notices"] == [lstm.SKIP_NOTICE]
    assert "LSTM skipped: torch not installed (pip install torch)" in capsys.readouterr().err


def test_runner_is_deterministic_and_reads_other_message_paths(tiny_logs: Tuple[List[str], str]) -> None:
    train, test = tiny_logs
    a = run.evaluate(train, test, seed=2, methods=["sk-gp-ekf"], gp_rows=60)
    b = run.evaluate(train, test, seed=2, methods=["sk-gp-ekf"], gp_rows=60)
    assert a["methods"]["sk-gp-ekf"]["rmse"] == b["methods"]["sk-gp-ekf"]["rmse"]
    # Swapping the roles of x and y gives a different problem: the paths are really used.
    swapped = {"u": "/input.data", "x": "/sensor.data", "y": "/state.data"}
    c = run.evaluate(train, test, swapped, seed=2, methods=["sk-gp-ekf"], gp_rows=60)
    assert c["methods"]["sk-gp-ekf"]["rmse"] != a["methods"]["sk-gp-ekf"]["rmse"]
    with pytest.raises(ValueError):
        run.evaluate(train, test, methods=["nope"])


def test_grid_writes_json_and_a_markdown_table(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    _hbn_or_skip()
    doc = run.grid(["duhem"], [1.0], [1], tmp_path, steps=120, methods=["hbn-ekf", "sk-gp-ekf"], gp_rows=60)
    saved = json.loads((tmp_path / "grid.json").read_text())
    assert saved["summary"] == json.loads(json.dumps(doc["summary"]))
    row = saved["summary"][0]
    assert (row["system"], row["gain"], row["runs"]) == ("duhem", 1.0, 1)
    hbn_nr, sk_nr = row["methods"]["hbn-ekf"]["nrmse"], row["methods"]["sk-gp-ekf"]["nrmse"]
    assert row["ratio_hbn-ekf"] == pytest.approx(hbn_nr / sk_nr)
    md = (tmp_path / "grid.md").read_text()
    assert md.startswith("| system | gain | runs |")
    assert f"| duhem | 1 | 1 | - | {hbn_nr:.4f} +- 0.0000 | - | - | {sk_nr:.4f}" in md
    # --table re-renders the same tables from the saved JSON.
    assert run.main(["--table", str(tmp_path / "grid.json")]) == 0
    assert capsys.readouterr().out == md


def test_the_floor_is_scored_on_simulated_logs_and_refused_on_others(tmp_path: Path) -> None:
    _hbn_or_skip()
    doc = run.grid(["duhem"], [3.0], [1], tmp_path, steps=150, methods=["sk-gp-ekf", "floor"], gp_rows=60)
    (row,) = doc["summary"]
    floor, sk = row["methods"]["floor"], row["methods"]["sk-gp-ekf"]
    # The floor conditions on more than any causal estimator: the baseline cannot beat it.
    assert floor["nrmse"] < sk["nrmse"]
    assert 0.85 <= floor["coverage_2sigma"] <= 1.0 and 0.6 < floor["mean_nees"] < 1.6
    md = (tmp_path / "grid.md").read_text()
    assert f"| {floor['nrmse']:.4f} | - |" in md  # no hbn in this run: no hbn / floor ratio
    with pytest.raises(ValueError, match="simulated logs"):
        run.evaluate(*_logs_for_floor(tmp_path), methods=["floor"])


def _logs_for_floor(tmp_path: Path) -> Tuple[List[str], str]:
    return run.simulate_logs("duhem", 1.0, 1, tmp_path / "logs", steps=60)


def test_summary_ratio_uses_the_best_baseline() -> None:
    def rep(nr: Dict[str, float]) -> Dict[str, object]:
        return {"methods": {k: {"nrmse": v, "coverage_1sigma": None, "coverage_2sigma": None,
                                "mean_nees": None, "train_seconds": 1.0} for k, v in nr.items()}}  # fmt: skip

    runs = [
        {"system": "s", "gain": 1.0, "seed": 1, "report": rep({"hbn-ekf": 0.02, "sk-gp-ekf": 0.04, "lstm": 0.05})},
        {"system": "s", "gain": 1.0, "seed": 2, "report": rep({"hbn-ekf": 0.04, "sk-gp-ekf": 0.06, "lstm": 0.03})},
    ]
    (row,) = run.summarise(runs)
    assert row["floor_ratio_hbn"] is None  # neither hbn's default mode nor the floor ran
    # Means: hbn 0.03, sklearn 0.05, LSTM 0.04 -> best baseline 0.04.
    assert row["ratio_hbn-ekf"] == pytest.approx(0.75)
    assert row["ratio_hbn-ekf-blr"] is None
    assert row["methods"]["hbn-ekf"]["nrmse_sd"] == pytest.approx(0.01)


def test_configurations_are_named_as_hbn_train_names_candidates() -> None:
    """The grid names a model's configuration as ``hbn train`` does, the sensor included when it
    is not the thesis' (so that a grid says which sensor a cell's model kept)."""
    assert run._name("matern52", "matern52", None, []) == "matern52 exact"
    assert run._name("se-ard", "matern52", 64, [1.0]) == "se-ard,matern52 m=64 lags=1"
    assert run._name("matern52", "matern52", None, [], "memory") == "matern52 exact sensor=memory"
    assert run._name("matern52", "matern52", 64, [], "thesis") == "matern52 m=64"
