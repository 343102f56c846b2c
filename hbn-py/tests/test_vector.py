"""Vector models in Python: several inputs, a vector state and several sensors, trained from
(T, d) arrays or lists of message paths, estimated in batch and by the streaming filter, and
carried through files, bytes and pickle bit for bit."""

import json
import pickle
import subprocess

import numpy as np
import pytest

import hbn
from conftest import find_hbn_bin, nrmse

FAST = dict(max_points=80, n_starts=1, max_iters=40, seed=0)


def coupled(n, seed):
    """A cross-coupled toy: two inputs drive two first-order states that each read both
    inputs; three sensors read both states (one of them nonlinearly), with a little noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.05
    u = np.column_stack([np.sin(t * (1.0 + 0.1 * seed)), np.cos(0.7 * t + seed)])
    x = np.zeros((n, 2))
    a = b = 0.0
    for k in range(n):
        a = 0.8 * a + 0.2 * (u[k, 0] + 0.3 * u[k, 1])
        b = 0.85 * b + 0.15 * (u[k, 1] - 0.2 * u[k, 0])
        x[k] = (a, b)
    y = np.column_stack(
        [x[:, 0] + 0.1 * x[:, 1], x[:, 1] - 0.05 * x[:, 0] ** 2, x[:, 0] + x[:, 1]]
    )
    return u, x, y + 0.002 * rng.standard_normal(y.shape)


@pytest.fixture(scope="module")
def vector():
    u, x, y = coupled(300, 1)
    model = hbn.HysteresisModel.fit(u, x, y, **FAST)
    return model, coupled(200, 2)


def bits(a):
    """The bit patterns of a float array (NaN-safe equality)."""
    return np.ascontiguousarray(a, dtype=np.float64).view(np.uint64)


def test_a_vector_model_smooths(vector):
    model, (u, x, y) = vector
    for mode in ("ekf", "ukf"):
        est = model.estimate(u, y, mode=mode)
        smo = model.smooth(u, y, mode=mode)
        assert smo.x.shape == est.x.shape == (200, 2) and smo.x_cov.shape == (200, 2, 2)
        np.testing.assert_array_equal(smo.nis, est.nis)
        assert np.all(np.isfinite(smo.x)) and np.all(smo.x_std <= est.x_std * (1 + 1e-9))
        np.testing.assert_allclose(smo.x[-1], est.x[-1], rtol=1e-12)
        diag = np.sqrt(np.diagonal(smo.x_cov, axis1=1, axis2=2))
        np.testing.assert_allclose(diag, smo.x_std, rtol=1e-12)
        assert np.abs(smo.x - est.x).max() > 1e-9
        for i in range(2):
            assert nrmse(smo.x[:, i], x[:, i]) < 0.05, (mode, i)
    with pytest.raises(ValueError, match="scalar"):
        model.smooth(u, y, mode="ekf-blr")
    with pytest.raises(ValueError, match="equal lengths"):
        model.smooth(u, y[:-1])


def test_a_vector_state_measured_sometimes_trains_by_em():
    # The state filmed at every fifth sample, one component's frames partly dropped: NaN
    # elsewhere. Training runs expectation-maximisation over the latent samples.
    u, x, y = coupled(300, 1)
    filmed = np.full_like(x, np.nan)
    filmed[::5] = x[::5]
    filmed[100:160:5, 1] = np.nan
    model = hbn.HysteresisModel.fit(u, filmed, y, **FAST)
    latent = model.summary["latent"]
    measured = np.isfinite(filmed).mean()
    assert abs(latent["observed"] - measured) < 1e-9, latent
    assert latent["frames"] == 60 and latent["rounds"][0]["round"] == 0, latent
    assert any("latent" in w for w in model.summary["warnings"])
    ut, xt, yt = coupled(200, 2)
    est = model.estimate(ut, yt)
    for i in range(2):
        assert nrmse(est.x[:, i], xt[:, i]) < 0.1, i
    with pytest.raises(hbn.DataError, match="no trajectory has a measured state"):
        hbn.HysteresisModel.fit(u, np.full_like(x, np.nan), y, **FAST)
    broken = filmed.copy()
    broken[7, 0] = np.inf
    with pytest.raises(hbn.DataError):
        hbn.HysteresisModel.fit(u, broken, y, **FAST)


def test_2d_arrays_train_a_vector_model_that_tracks_both_components(vector):
    model, (u, x, y) = vector
    assert model.is_vector and model.dims == (2, 2, 3)
    assert "vector" in repr(model)
    est = model.estimate(u, y)
    for i in range(2):
        assert nrmse(est.x[:, i], x[:, i]) < 0.05, i
    s = est.score(x)
    assert s["nrmse"].shape == (2,) and np.all(s["nrmse"] < 0.05)
    assert list(s["samples"]) == [200, 200]
    assert len(model.transition_gps) == 2 and len(model.sensor_gps) == 3
    memory = len(model.params["memory"])
    assert model.transition_gps[0].n_features_in_ == 2 * 2 + 2 * (2 + memory)
    assert model.summary["trajectories"] == 1 and model.summary["validation"]
    assert model.summary["kernel_evidence"] == []


def test_a_list_of_kernels_is_chosen_among_by_evidence_per_gp():
    u, x, y = coupled(300, 1)
    model = hbn.HysteresisModel.fit(u, x, y, kernel=["matern52", "se-ard"], **FAST)
    rows = model.summary["kernel_evidence"]
    # Two rows per GP: two transitions and both variants of each of three sensors.
    assert len(rows) == 2 * (2 + 2 * 3)
    assert sum(r["chosen"] for r in rows) == 2 + 2 * 3


def test_exact_and_sparse_gps_with_each_lag_set_are_the_candidates(vector):
    model, _ = vector
    rows = model.summary["candidates"]
    shapes = [(r["n_inducing"], tuple(r["lags"])) for r in rows]
    assert shapes == [(m, lags) for m in (None, 64) for lags in ((), (0.1,), (1.0,))]
    assert sum(r["chosen"] for r in rows) == 1
    chosen = next(r for r in rows if r["chosen"])
    assert model.params["n_inducing"] == chosen["n_inducing"]


def test_a_vector_model_refuses_a_flash_budget():
    u, x, y = coupled(120, 1)
    with pytest.raises(hbn.ConfigError, match="--inducing"):
        hbn.HysteresisModel.fit(u, x, y, firmware_budget="64KB", **FAST)


def test_estimate_shapes_for_1d_column_and_vector_data(vector):
    model, (u, _, y) = vector
    est = model.estimate(u, y)
    assert est.x.shape == est.x_std.shape == (200, 2)
    assert est.x_cov.shape == (200, 2, 2)
    assert est.y_pred.shape == est.innovation.shape == (200, 3)
    assert est.nis.shape == est.flags.shape == (200,)
    assert est.unobservable.shape == (2,)
    assert est.q_x is None and est.obs_x is None
    assert np.allclose(est.x_cov[:, [0, 1], [0, 1]], est.x_std**2)
    x_hat, x_std = est
    assert x_hat is est.x and "q_x" not in est.to_dict() and "x_cov" in est.to_dict()

    d = hbn.simulate("duhem", 200, seed=1)
    scalar = hbn.HysteresisModel.fit(d["u"], d["x"], d["y"], **FAST)
    flat = scalar.estimate(d["u"], d["y"])
    assert flat.x.shape == (200,) and flat.x_cov is None and flat.q_x.shape == (200,)
    col = scalar.estimate(d["u"].reshape(-1, 1), d["y"].reshape(-1, 1))
    assert col.x.shape == col.x_std.shape == col.y_pred.shape == (200, 1)
    assert np.array_equal(bits(col.x[:, 0]), bits(flat.x))
    assert col.score(d["x"].reshape(-1, 1))["nrmse"].shape == (1,)

    # (T, 1) arrays everywhere train the scalar model, with the same numbers.
    column = hbn.HysteresisModel.fit(
        d["u"].reshape(-1, 1), d["x"].reshape(-1, 1), d["y"].reshape(-1, 1), **FAST
    )
    assert not column.is_vector and column.dims == (1, 1, 1)
    assert column.to_bytes() == scalar.to_bytes()


def test_a_single_input_or_sensor_may_be_1d(vector):
    u, x, y = coupled(200, 3)
    model = hbn.HysteresisModel.fit(u[:, :1], x, y[:, :1], **FAST)
    assert model.dims == (1, 2, 1)
    a = model.estimate(u[:, 0], y[:, 0])
    b = model.estimate(u[:, :1], y[:, :1])
    assert a.x.shape == (200, 2) and np.array_equal(bits(a.x), bits(b.x))


def test_the_filter_steps_equal_the_estimate_bit_for_bit(vector):
    model, (u, _, y) = vector
    y = y.copy()
    y[50, 1] = np.nan  # a sensor's dropout: left out of that update
    for mode in ("ekf", "ukf"):
        est = model.estimate(u, y, mode=mode)
        f = model.filter(mode=mode)
        assert f.mode == mode
        for _ in range(2):
            for k in range(len(u)):
                out = f.step(u[k], list(y[k]))
                assert isinstance(out, hbn.VectorFilterOutput)
                assert np.array_equal(bits(out.x), bits(est.x[k])), (mode, k)
                assert np.array_equal(bits(out.x_std), bits(est.x_std[k]))
                assert np.array_equal(bits(out.x_cov), bits(est.x_cov[k]))
                assert np.array_equal(bits(out.y_pred), bits(est.y_pred[k]))
                assert np.array_equal(bits(out.innovation), bits(est.innovation[k]))
                assert bits([out.nis]) == bits([est.nis[k]]) and out.flags == est.flags[k]
            assert f.steps == len(u)
            f.reset()
            assert f.steps == 0
    assert "initialised" in model.filter().step(u[0], y[0]).flag_names()
    assert len(out.q_x) == 2 and len(out.r) == 3 and len(out.innovation_var) == 3


def test_bytes_pickle_and_files_round_trip_bit_for_bit(vector, tmp_path):
    model, (u, _, y) = vector
    data = model.to_bytes()
    assert b'"format":"hbn-vector-model"' in data
    est = model.estimate(u, y)
    p = tmp_path / "finger.hbn"
    model.save(p)
    assert p.read_bytes() == data
    for copy in (
        hbn.HysteresisModel.from_bytes(data),
        pickle.loads(pickle.dumps(model, protocol=5)),
        hbn.HysteresisModel.load(p),
    ):
        assert copy.is_vector and copy.to_bytes() == data
        again = copy.estimate(u, y)
        for k in ("x", "x_std", "x_cov", "y_pred", "innovation", "nis"):
            assert np.array_equal(bits(getattr(again, k)), bits(getattr(est, k))), k
    assert copy.default_mode == model.default_mode and copy.params == model.params


def test_scalar_only_methods_and_the_explorer_say_so(vector):
    model, (u, _, _) = vector
    for call in (
        lambda: model.simulate_open_loop(u[:, 0]),
        lambda: model.initial_state(0.1),
        lambda: model.tuning,
        lambda: model.transition,
        lambda: model.sensor,
    ):
        with pytest.raises(ValueError, match="takes scalar models.*vector model of 2 inputs"):
            call()
    explorer = hbn.Explorer(0.0, 1.0, 0.05, random_samples=10, max_points=40, n_starts=1)
    with pytest.raises(ValueError, match="Explorer takes scalar models"):
        explorer.observe([0.1, 0.2], [0.0, 0.1], [0.3, 0.2, 0.1])
    with pytest.raises(ValueError, match="Explorer takes scalar models.*u_min has 2 values"):
        hbn.Explorer([0.0, 0.0], [1.0, 1.0], 0.05)
    assert explorer.n_observed == 0
    cfg = model.ekf_config()
    assert cfg["mode"] == model.default_mode and len(cfg["x_bounds"]) == 3


def test_mismatched_shapes_are_data_errors(vector):
    model, (u, x, y) = vector
    with pytest.raises(hbn.DataError, match=r"all be 1-D .* or all 2-D"):
        hbn.HysteresisModel.fit(u, x[:, 0], y, **FAST)
    with pytest.raises(hbn.DataError, match="every trajectory of y must have the same columns"):
        hbn.HysteresisModel.fit([u, u], [x, x], [y, y[:, :2]], **FAST)
    with pytest.raises(hbn.DataError, match="1 to 4 inputs, 1 to 3 state components"):
        hbn.HysteresisModel.fit(np.tile(u, (1, 3)), x, y, **FAST)
    with pytest.raises(hbn.DataError, match="equal lengths"):
        hbn.HysteresisModel.fit(u, x[:-1], y, **FAST)
    with pytest.raises(hbn.DataError, match=r"y must have shape \(T, 3\).*got shape \(200, 2\)"):
        model.estimate(u, y[:, :2])
    with pytest.raises(hbn.DataError, match="u and y must have equal lengths"):
        model.estimate(u[:-1], y)
    with pytest.raises(hbn.DataError, match="step takes 2 inputs and 3 measurements"):
        model.filter().step([0.1], [0.0, 0.0, 0.0])
    with pytest.raises(hbn.ConfigError, match="signals"):
        hbn.HysteresisModel.fit(u, x, y, signals={"u": ["/a.data"]}, **FAST)
    d = hbn.simulate("duhem", 100, seed=1)
    scalar = hbn.HysteresisModel.fit(d["u"], d["x"], d["y"], **FAST)
    with pytest.raises(hbn.DataError, match=r"u must have shape \(T, 1\)"):
        scalar.estimate(np.column_stack([d["u"], d["u"]]), d["y"])


def test_sensor_inputs_apply_to_every_sensor_or_one_each():
    u, x, y = coupled(200, 5)
    dims = lambda m: [g.n_features_in_ for g in m.sensor_gps]  # noqa: E731
    # 2 dx + 1 with the sensor's previous output (the thesis' inputs), 2 dx with the state only.
    assert dims(hbn.HysteresisModel.fit(u, x, y, sensor_inputs="state", **FAST)) == [4, 4, 4]
    each = hbn.HysteresisModel.fit(u, x, y, sensor_inputs=["state", "thesis", "state"], **FAST)
    assert dims(each) == [4, 5, 4]
    with pytest.raises(hbn.ConfigError, match="one per sensor") as e:
        hbn.HysteresisModel.fit(u, x, y, sensor_inputs=["state", "thesis"], **FAST)
    assert e.value.keyword == "sensor_inputs"


def test_signal_names_are_kept(vector):
    u, x, y = coupled(150, 4)
    names = {"u": ["/valve0.p", "/valve1.p"], "x": ["/tip.x", "/tip.y"], "y": ["/s0.v", "/s1.v", "/s2.v"]}
    model = hbn.HysteresisModel.fit(u, x, y, signals=names, **FAST)
    assert model.signals == {
        "inputs": names["u"],
        "states": names["x"],
        "outputs": names["y"],
    }


@pytest.fixture(scope="module")
def finger_logs(tmp_path_factory):
    exe = find_hbn_bin()
    if exe is None:
        pytest.skip("no hbn CLI binary: set HBN_BIN or build target/release/hbn")
    d = tmp_path_factory.mktemp("finger")
    logs = []
    for name, steps, seed in (("train", 600, 1), ("test", 300, 2)):
        path = d / f"{name}.mcap"
        subprocess.run(
            [exe, "simulate", "--system", "finger", "--steps", str(steps), "--seed", str(seed),
             "--noise-gain", "1", "--out", str(path)],
            check=True, capture_output=True,
        )
        logs.append(path)
    return exe, logs


def test_simulate_gives_the_finger_of_the_cli(finger_logs):
    _, (_, test) = finger_logs
    assert hbn.MULTI_SYSTEMS == ("finger", "arm")
    d = hbn.simulate("finger", 300, seed=2, noise_gain=1)
    assert d["u"].shape == (300, 2) and d["x"].shape == (300, 2) and d["y"].shape == (300, 3)
    # The samples of `hbn simulate --system finger --steps 300 --seed 2 --noise-gain 1` (to the
    # rounding of reading them back on a grid).
    logged = hbn.read_mcap(test, {"x0": "/state.x0", "x1": "/state.x1", "y2": "/sensor2.data"})
    for got, want in ((logged["x0"], d["x"][:, 0]), (logged["x1"], d["x"][:, 1]),
                      (logged["y2"], d["y"][:, 2])):
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-15)
    arm = hbn.simulate("ARM", 50, seed=1)
    assert arm["x"].shape == (50, 3) and arm["y"].shape == (50, 4)
    with pytest.raises(ValueError, match="system"):
        hbn.simulate("hand", 50)


def test_from_logs_with_lists_of_paths_trains_on_the_finger(finger_logs, tmp_path):
    exe, (train, test) = finger_logs
    inputs = ["/input0.data", "/input1.data"]
    states = ["/state.x0", "/state.x1"]
    outputs = ["/sensor0.data", "/sensor1.data", "/sensor2.data"]
    model = hbn.HysteresisModel.from_logs(
        [train], input=inputs, state=states, output=outputs, **FAST
    )
    assert model.is_vector and model.dims == (2, 2, 3)
    assert model.signals == {"inputs": inputs, "states": states, "outputs": outputs}
    csv = tmp_path / "finger.csv"
    est = model.estimate_log(test, csv=csv)
    assert est.x.shape == (300, 2) and est.t.shape == (300,)
    truth = hbn.read_mcap(test, {"x0": "/state.x0", "x1": "/state.x1"}, rate_hz=model.rate_hz)
    for i in range(2):
        assert nrmse(est.x[:, i], truth[f"x{i}"]) < 0.1, i
    header = csv.read_text().splitlines()[0].split(",")
    assert header[:5] == ["t", "x0", "x0_std", "x1", "x1_std"]
    out = tmp_path / "finger_estimate.mcap"
    again = model.estimate_log(test, mcap=out)
    assert np.array_equal(bits(again.x), bits(est.x))
    topics = hbn.list_topics(out)
    assert len(topics) == 1 and topics[0]["message_count"] == 300

    # The CLI estimates with the file Python wrote, and writes the same CSV.
    path = tmp_path / "finger.hbn"
    model.save(path)
    cli_csv, cli_mcap = tmp_path / "cli.csv", tmp_path / "cli.mcap"
    subprocess.run(
        [exe, "estimate", "--model", str(path), "--log", str(test), "--csv", str(cli_csv),
         "--out", str(cli_mcap)],
        check=True, capture_output=True,
    )
    assert cli_csv.read_bytes() == csv.read_bytes()
    assert cli_mcap.read_bytes() == out.read_bytes()

    # hbn train with the same flags trains the same model (the files differ only in the
    # wall-clock seconds they record).
    cli_model = tmp_path / "cli.hbn"
    flags = [f"--{kind}={p}" for kind, ps in (("input", inputs), ("state", states),
                                              ("output", outputs)) for p in ps]
    subprocess.run(
        [exe, "train", "--log", str(train), *flags, "--max-points", "80", "--starts", "1",
         "--max-iters", "40", "--seed", "0", "--out", str(cli_model)],
        check=True, capture_output=True,
    )

    def timeless(v):
        if isinstance(v, dict):
            return {k: timeless(x) for k, x in v.items() if k != "seconds"}
        return [timeless(x) for x in v] if isinstance(v, list) else v

    assert timeless(json.loads(cli_model.read_bytes())) == timeless(json.loads(model.to_bytes()))
    assert hbn.HysteresisModel.load(cli_model).is_vector

    # One path per kind stays a scalar model (here: one input, one state, one sensor).
    scalar = hbn.HysteresisModel.from_logs(
        train, input=["/input0.data"], state=["/state.x0"], output="/sensor0.data", **FAST
    )
    assert not scalar.is_vector
