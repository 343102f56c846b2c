"""The pipeline shared with the CLI: training from logs gives the CLI's model file byte for byte
(also at 50 Hz), the model keeps the log's rate, estimates written from Python equal the CLI's,
the streaming filter equals batch estimation bit for bit, and every parameter check names the
keyword argument to change."""

import subprocess

import numpy as np
import pytest

import hbn
from conftest import find_hbn_bin


@pytest.fixture(scope="module")
def cli():
    exe = find_hbn_bin()
    if exe is None:
        pytest.skip("no hbn CLI binary: set HBN_BIN or build target/release/hbn")

    def run(*args):
        r = subprocess.run([exe, "--quiet", *map(str, args)], capture_output=True, text=True, timeout=900)
        assert r.returncode == 0, f"hbn {' '.join(map(str, args))} failed:\n{r.stdout}\n{r.stderr}"
        return r.stdout

    return run


def _logs(cli, d, rate, n=2):
    paths = []
    for s in range(n):
        p = d / f"train{s}-{rate:g}hz.mcap"
        cli("simulate", "--system", "duhem", "--steps", 500, "--seed", 10 + s, "--input-seed", 1,
            "--rate", rate, "--noise-gain", 1, "--out", p)
        paths.append(p)
    return paths


@pytest.mark.parametrize("rate", [50.0, 100.0])
def test_from_logs_gives_the_cli_model_file_byte_for_byte(cli, tmp_path, rate):
    logs = _logs(cli, tmp_path, rate)
    cli_model = tmp_path / "cli.hbn"
    args = ["train", "--max-points", 120, "--starts", 1, "--max-iters", 40, "--seed", 3]
    for p in logs:
        args += ["--log", p]
    cli(*args, "--out", cli_model)
    model = hbn.HysteresisModel.from_logs(logs, max_points=120, n_starts=1, max_iters=40, seed=3)
    # The model keeps the logs' rate (not a default of 100 Hz).
    assert model.rate_hz == rate
    py_model = tmp_path / "py.hbn"
    model.save(py_model)
    assert py_model.read_bytes() == cli_model.read_bytes()
    # Defaults are the library's: what Python records equals what `hbn train` records.
    loaded = hbn.HysteresisModel.load(cli_model)
    assert loaded.params == model.params
    assert loaded.signals["input"]["path"] == "/input.data"


def test_estimates_written_from_python_equal_the_cli(cli, tmp_path):
    logs = _logs(cli, tmp_path, 50.0, n=1)
    model_path = tmp_path / "m.hbn"
    cli("train", "--log", logs[0], "--max-points", 100, "--starts", 1, "--out", model_path)
    test = tmp_path / "test.mcap"
    cli("simulate", "--system", "duhem", "--steps", 300, "--seed", 99, "--rate", 50, "--out", test)
    cli("estimate", "--model", model_path, "--log", test, "--mode", "ekf-blr",
        "--csv", tmp_path / "cli.csv", "--out", tmp_path / "cli.mcap")
    model = hbn.HysteresisModel.load(model_path)
    est = model.estimate_log(test, mode="ekf-blr", csv=tmp_path / "py.csv", mcap=tmp_path / "py.mcap")
    assert (tmp_path / "py.csv").read_bytes() == (tmp_path / "cli.csv").read_bytes()
    # Read back through resampling (grid times rounded to ns): equal up to interpolation rounding.
    back = hbn.read_mcap(tmp_path / "py.mcap", {"x": "/hbn/estimate.x"}, rate_hz=50.0)
    np.testing.assert_allclose(back["x"], est.x, rtol=0, atol=1e-12)
    assert est.t is not None and est.t[1] == pytest.approx(0.02)
    # The same numbers as the array API on the same grid.
    d = hbn.read_mcap(test, {"u": "/input.data", "y": "/sensor.data"}, rate_hz=model.rate_hz)
    np.testing.assert_array_equal(model.estimate(d["u"], d["y"], mode="ekf-blr").x, est.x)


def test_streaming_filter_equals_batch_bit_for_bit(trained):
    model, _, test = trained
    u, y = test["u"].copy(), test["y"].copy()
    u[30] = np.nan
    y[31] = np.nan
    for mode in hbn.MODES:
        batch = model.estimate(u, y, mode=mode)
        f = model.filter(mode=mode)
        assert f.mode == mode and f.steps == 0
        for rnd in range(2):
            outs = [f.step(a, b) for a, b in zip(u, y)]
            for name in ("x", "x_std", "y_pred", "innovation", "nis", "q_x", "r", "obs_min", "obs_max", "obs_x"):
                got = np.array([getattr(o, name) for o in outs])
                np.testing.assert_array_equal(got, getattr(batch, name), err_msg=f"{mode} {name}")
            assert [o.flags for o in outs] == list(batch.flags)
            assert "input_invalid" in outs[30].flag_names()
            assert f.steps == len(u)
            f.reset()
    # The first step takes the prior from the first measurement.
    mean, var = model.initial_state(y[0])
    first = model.filter().step(u[0], y[0])
    # The reported std carries the default mode's learned std scale (filter-aware training).
    scale = model.ekf_config(model.default_mode)["std_scale"]
    assert first.x == mean and first.x_std == pytest.approx(scale * np.sqrt(var), rel=1e-9)


def test_defaults_come_from_the_library():
    p = hbn.default_params()
    tr = hbn.simulate("duhem", 200, seed=1)
    m = hbn.HysteresisModel.fit(tr["u"], tr["x"], tr["y"], max_points=60)
    got = m.params
    for k, v in p.items():
        if k in ("kernel", "transition_kernel", "sensor_kernel"):
            # None by default: each GP chooses by evidence; the model holds the kernel chosen.
            assert v is None and (k == "kernel" or got[k] in ("matern52", "se-ard")), k
        elif k not in ("max_points", "signals", "n_inducing", "lags", "sensor_inputs"):
            assert got[k] == v, k
    assert got["max_points"] == 60
    # The default lists the inducing settings chosen among on held-out data (exact GPs first);
    # the model holds the one chosen.
    assert p["n_inducing"] == [None, hbn.DEFAULT_INDUCING]
    assert got["n_inducing"] in p["n_inducing"]
    # Likewise the lag sets (the primary one first).
    assert p["lags"] == [[], [1.0]] and got["lags"] in p["lags"]
    # And the sensor's inputs (the thesis' sensor first, a sensor with memory tried).
    assert p["sensor_inputs"] == ["thesis", "memory"] and got["sensor_inputs"] in p["sensor_inputs"]
    o = hbn.default_log_options()
    assert o["rate_hz"] is None and o["max_gap_s"] > 0 and o["time_source"] == "log"
    assert hbn.default_gp_params()["n_starts"] >= 1


def test_exception_classes():
    assert issubclass(hbn.DataError, hbn.HbnError) and issubclass(hbn.DataError, ValueError)
    assert issubclass(hbn.ConfigError, hbn.HbnError) and issubclass(hbn.ConfigError, ValueError)
    assert issubclass(hbn.ModelFileError, hbn.HbnError)
    assert issubclass(hbn.HbnIOError, OSError) and issubclass(hbn.HbnIOError, hbn.HbnError)
    assert issubclass(hbn.HbnFileNotFoundError, FileNotFoundError)
    assert issubclass(hbn.HbnFileNotFoundError, hbn.HbnIOError)
    assert issubclass(hbn.TrainingError, hbn.HbnError) and issubclass(hbn.TrainingError, RuntimeError)


BAD_PARAMS = [
    ("rate_hz", -1.0),
    ("rate_hz", 0),
    ("max_points", 1),
    ("n_starts", 0),
    ("max_iters", 0),
    ("noise_floor", 0.0),
    ("blr_window", 0.7),
    ("blr_window", 0.0),
    ("kernel", "rbf"),
    ("transition_kernel", "rbf"),
    ("sensor_kernel", "rbf"),
    ("subset_policy", "all"),
    ("seed", -1),
    ("normalize", "yes"),
    ("memory", [0.0]),
    ("memory", [1.5]),
    ("memory", [0.1] * 5),
    ("memory", "lots"),
    ("lags", [0.0]),
    ("lags", [-1.0]),
    ("lags", [1.0] * 3),
    ("lags", "slow"),
    ("linear_mean", "sensor"),
    ("linear_mean", 1),
    ("max_signal_variance", 0.0),
    ("max_signal_variance", "lots"),
    ("sensor_inputs", "level"),
    ("sensor_inputs", 2),
]


def test_memory_sets_the_play_operators():
    d = hbn.simulate("preisach", 300, seed=1, noise_gain=1.0)
    fast = dict(max_points=80, n_starts=1, max_iters=30, validation=0.0)
    default = hbn.HysteresisModel.fit(d["u"], d["x"], d["y"], **fast)
    assert default.params["memory"] == hbn.default_params()["memory"] == [0.05, 0.2]
    plain = hbn.HysteresisModel.fit(d["u"], d["x"], d["y"], memory=[], **fast)
    assert plain.params["memory"] == []
    one = hbn.HysteresisModel.fit(d["u"], d["x"], d["y"], memory=0.3, **fast)
    assert one.params["memory"] == [0.3]
    te = hbn.simulate("preisach", 200, seed=2, noise_gain=1.0)
    a, _ = default.estimate(te["u"], te["y"])
    b, _ = plain.estimate(te["u"], te["y"])
    assert not np.array_equal(a, b)


def test_lags_set_low_pass_inputs_of_the_transition():
    d = hbn.simulate("soft-actuator", 300, seed=1, noise_gain=1.0)
    fast = dict(max_points=80, n_starts=1, max_iters=30, validation=0.0)
    # The default trains none and tries one 1 s lag on held-out data (none here: validation=0).
    assert hbn.default_params()["lags"] == [[], [1.0]]
    plain = hbn.HysteresisModel.fit(d["u"], d["x"], d["y"], **fast)
    assert plain.params["lags"] == []
    lagged = hbn.HysteresisModel.fit(d["u"], d["x"], d["y"], lags=[1.0], **fast)
    assert lagged.params["lags"] == [1.0]
    assert lagged.params["memory"] == [0.05, 0.2]
    te = hbn.simulate("soft-actuator", 200, seed=2, noise_gain=1.0)
    a, _ = plain.estimate(te["u"], te["y"])
    b, _ = lagged.estimate(te["u"], te["y"])
    assert not np.array_equal(a, b)


def test_linear_mean_sets_the_gps_prior_means():
    d = hbn.simulate("preisach", 300, seed=1, noise_gain=1.0)
    fast = dict(max_points=80, n_starts=1, max_iters=30, validation=0.0, memory=[])
    assert hbn.default_params()["linear_mean"] == "none"
    te = hbn.simulate("preisach", 200, seed=2, noise_gain=1.0)
    estimates = []
    for choice in ["none", "transition", "both"]:
        model = hbn.HysteresisModel.fit(d["u"], d["x"], d["y"], linear_mean=choice, **fast)
        assert model.params["linear_mean"] == choice
        x, _ = model.estimate(te["u"], te["y"])
        estimates.append(x)
    assert not np.array_equal(estimates[0], estimates[1])
    assert not np.array_equal(estimates[1], estimates[2])


def test_sensor_inputs_set_what_the_sensor_gp_reads():
    d = hbn.simulate("maxwell-slip", 300, seed=1, noise_gain=1.0)
    fast = dict(max_points=80, n_starts=1, max_iters=30, validation=0.0)
    thesis = hbn.HysteresisModel.fit(d["u"], d["x"], d["y"], **fast)
    assert thesis.params["sensor_inputs"] == "thesis"
    state = hbn.HysteresisModel.fit(d["u"], d["x"], d["y"], sensor_inputs="state", **fast)
    assert state.params["sensor_inputs"] == "state"
    te = hbn.simulate("maxwell-slip", 200, seed=2, noise_gain=1.0)
    a, _ = thesis.estimate(te["u"], te["y"])
    b, b_std = state.estimate(te["u"], te["y"])
    assert np.all(np.isfinite(b)) and np.all(b_std > 0)
    assert not np.array_equal(a, b)
    # A list: the first is the primary one, the rest tried on held-out data.
    both = hbn.HysteresisModel.fit(
        d["u"], d["x"], d["y"], sensor_inputs=["state", "thesis"], **fast
    )
    assert both.params["sensor_inputs"] == "state"  # validation=0: the primary one


@pytest.mark.parametrize("keyword,value", BAD_PARAMS)
def test_every_parameter_check_names_its_keyword(keyword, value):
    d = hbn.simulate("duhem", 50, seed=1)
    with pytest.raises(hbn.ConfigError, match=keyword) as e:
        hbn.HysteresisModel.fit(d["u"], d["x"], d["y"], **{keyword: value})
    assert e.value.keyword == keyword


@pytest.mark.parametrize(
    "keyword,kwargs",
    [
        ("max_gap_s", {"max_gap_s": 0.0}),
        ("time_source", {"time_source": "gps"}),
        ("rate_hz", {"rate_hz": -2.0}),
        ("input", {"input": "/a[x"}),
        ("logs", {"logs": []}),
        ("max_points", {"max_points": 1}),
    ],
)
def test_log_option_checks_name_their_keyword_before_reading(keyword, kwargs, tmp_path):
    kwargs = dict(kwargs)
    paths = kwargs.pop("logs", [tmp_path / "absent.mcap"])
    with pytest.raises(hbn.ConfigError, match=keyword) as e:
        hbn.HysteresisModel.from_logs(paths, **kwargs)
    assert e.value.keyword == keyword


def test_unknown_keyword_is_a_type_error():
    d = hbn.simulate("duhem", 50, seed=1)
    with pytest.raises(TypeError, match="max_pointz"):
        hbn.HysteresisModel.fit(d["u"], d["x"], d["y"], max_pointz=10)


def test_summary_reports_every_start(trained):
    model, _, _ = trained
    s = model.summary
    assert isinstance(s, dict) and s["trajectories"] == 1
    assert [st["gp"] for st in s["starts"]] == ["transition", "sensor"]
    for st in s["starts"]:
        t = st["termination"]
        assert t["termination"] in ("converged", "max-iters", "solver-exit", "failed"), t
        assert t["termination"] != "solver-exit" or t["reason"], t
    assert isinstance(model.transition.report_, dict)
