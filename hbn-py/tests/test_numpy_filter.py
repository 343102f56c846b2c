"""The numpy baseline of benches/numpy_filter.py is the same filter as hbn's EKF."""

import numpy as np
import pytest

import hbn
import numpy_filter  # benches/, put on sys.path by conftest


@pytest.mark.parametrize("kernel", ["matern52", "thesis", "se-ard"])
def test_numpy_filter_matches_hbn(kernel, tmp_path):
    train = hbn.simulate("duhem", 500, seed=3, noise_gain=1.0)
    model = hbn.HysteresisModel.fit(
        train["u"], train["x"], train["y"], kernel=kernel, max_points=200, n_starts=1
    )
    path = tmp_path / "model.hbn"
    model.save(path)
    test = hbn.simulate("duhem", 300, seed=4, noise_gain=1.0)
    est = model.estimate(test["u"], test["y"], mode="ekf")  # the numpy filter is the EKF
    x_np, std_np = numpy_filter.numpy_estimate(
        numpy_filter.load_model_json(str(path)), test["u"], test["y"]
    )
    assert np.max(np.abs(x_np - est.x)) < 1e-6
    assert np.max(np.abs(std_np - est.x_std)) < 1e-6


def test_numpy_filter_matches_hbn_with_sparse_gps(tmp_path):
    """An independent implementation of the sparse predictor (dense numpy mat-vecs) inside the
    same filter gives hbn's estimates."""
    train = hbn.simulate("duhem", 1500, seed=3, noise_gain=1.0)
    model = hbn.HysteresisModel.fit(
        train["u"], train["x"], train["y"], n_inducing=24, n_starts=1
    )
    assert model.transition.is_sparse and model.sensor.is_sparse
    path = tmp_path / "model.hbn"
    model.save(path)
    test = hbn.simulate("duhem", 300, seed=4, noise_gain=1.0)
    est = model.estimate(test["u"], test["y"], mode="ekf")  # the numpy filter is the EKF
    x_np, std_np = numpy_filter.numpy_estimate(
        numpy_filter.load_model_json(str(path)), test["u"], test["y"]
    )
    assert np.max(np.abs(x_np - est.x)) < 1e-6
    assert np.max(np.abs(std_np - est.x_std)) < 1e-6


def test_numpy_gp_matches_hbn_gp(trained):
    model, _, test = trained
    doc = numpy_filter.load_model_json  # noqa: F841 (API presence)
    import json

    tr = json.loads(model._core.to_json())["model"]["transition"]
    ngp = numpy_filter.NumpyGP(tr)
    X = np.column_stack([test["x"][1:-1], test["x"][:-2], test["u"][1:-1], test["u"][:-2]])[:50]
    # The transition also reads the play operators' values (docs/memory.md): any values near
    # the input do for comparing the two GPs.
    extra = ngp.d - X.shape[1]
    X = np.column_stack([X] + [X[:, 2] + 0.01 * (j + 1) for j in range(extra)])
    mean, std, grad = model.transition.predict(X, return_std=True, return_grad=True)
    for i in range(len(X)):
        m, v, g = ngp.predict(X[i])
        # Same formulae, different summation order: rounding is amplified by |alpha| (large
        # when the learned noise is small), so agreement is to ~1e-8 of the signal, not 1e-15.
        assert abs(m - mean[i]) < 1e-7 * max(1.0, abs(mean[i]))
        assert abs(np.sqrt(v) - std[i]) < 1e-7
        np.testing.assert_allclose(g, grad[i], rtol=1e-6, atol=1e-7)


def test_bench_compare_runs():
    r = numpy_filter.compare(steps=150, max_points=80, train_steps=300)
    assert r["max_abs_diff_x"] < 1e-6 and r["ratio"] > 0


def test_numpy_filter_matches_hbn_with_linear_means(tmp_path):
    """Models with a linear prior mean on both GPs (model format 4): the numpy predictor adds
    the plane's slopes, and the filters agree."""
    train = hbn.simulate("duhem", 800, seed=3, noise_gain=1.0)
    model = hbn.HysteresisModel.fit(
        train["u"], train["x"], train["y"], max_points=200, n_starts=1, linear_mean="both"
    )
    path = tmp_path / "model.hbn"
    model.save(path)
    doc = numpy_filter.load_model_json(str(path))
    assert len(doc["transition"]["linear"]) == len(doc["transition"]["input_mean"])
    test = hbn.simulate("duhem", 300, seed=4, noise_gain=1.0)
    est = model.estimate(test["u"], test["y"], mode="ekf")
    x_np, std_np = numpy_filter.numpy_estimate(doc, test["u"], test["y"])
    assert np.max(np.abs(x_np - est.x)) < 1e-6
    assert np.max(np.abs(std_np - est.x_std)) < 1e-6


@pytest.mark.parametrize(
    "system, sensor_inputs, sensor_dim",
    [("maxwell-slip", "state", 2), ("duhem", "memory", 3)],
)
def test_numpy_filter_matches_hbn_with_other_sensors(tmp_path, system, sensor_inputs, sensor_dim):
    """A sensor GP on [x_{k-1}, x_k] (``sensor_inputs="state"``), or on the state and two plays
    of it (``"memory"``: the filter carries the plays of its own estimates, and a play passes
    its slope on only while the state drags it): the numpy filter, written apart from hbn-core,
    builds the sensor's input and its Jacobian row itself, and the two filters agree."""
    train = hbn.simulate(system, 800, seed=3, noise_gain=1.0)
    model = hbn.HysteresisModel.fit(
        train["u"],
        train["x"],
        train["y"],
        max_points=200,
        n_starts=1,
        n_inducing=None,
        lags=[],
        sensor_inputs=sensor_inputs,
    )
    path = tmp_path / "model.hbn"
    model.save(path)
    doc = numpy_filter.load_model_json(str(path))
    assert len(doc["sensor"]["input_mean"]) == sensor_dim
    assert len(doc.get("sensor_memory_radii", [])) == (2 if sensor_inputs == "memory" else 0)
    test = hbn.simulate(system, 300, seed=4, noise_gain=1.0)
    est = model.estimate(test["u"], test["y"], mode="ekf")
    x_np, std_np = numpy_filter.numpy_estimate(doc, test["u"], test["y"])
    assert np.max(np.abs(x_np - est.x)) < 1e-6
    assert np.max(np.abs(std_np - est.x_std)) < 1e-6
