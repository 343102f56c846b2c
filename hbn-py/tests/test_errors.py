"""Bad inputs raise the right Python exceptions with clear messages (never a panic)."""

import numpy as np
import pytest

import hbn


def test_gp_bad_data():
    X = np.linspace(0, 1, 10)
    y = np.sin(X)
    with pytest.raises(ValueError, match="non-finite"):
        hbn.GaussianProcess().fit(np.where(X > 0.5, np.nan, X), y)
    with pytest.raises(ValueError, match="same number of samples"):
        hbn.GaussianProcess().fit(X, y[:-1])
    with pytest.raises(hbn.ConfigError, match="invalid kernel='rbf': choose one of matern52"):
        hbn.GaussianProcess(kernel="rbf").fit(X, y)
    with pytest.raises(ValueError, match="length scale"):
        hbn.GaussianProcess(lengthscales=[1.0, 2.0], optimize=False).fit(X, y)
    with pytest.raises(ValueError, match="direction"):
        hbn.GaussianProcess(kernel="thesis").fit(X, y)  # the direction factor needs 2 features
    with pytest.raises(ValueError, match="not fitted"):
        hbn.GaussianProcess().predict([0.0])
    gp = hbn.GaussianProcess(optimize=False).fit(X, y)
    with pytest.raises(ValueError, match="features"):
        gp.predict(np.zeros((2, 3)))
    with pytest.raises(ValueError):
        gp.predict([np.nan])
    with pytest.raises(hbn.ConfigError, match=r"invalid n_starts=-1: must be >= 0"):
        hbn.GaussianProcess(n_starts=-1).fit(X, y)


def test_model_bad_data():
    d = hbn.simulate("duhem", 50, seed=1)
    with pytest.raises(hbn.DataError, match="equal lengths"):
        hbn.HysteresisModel.fit(d["u"], d["x"][:-1], d["y"])
    u = d["u"].copy()
    u[7] = np.nan
    with pytest.raises(ValueError, match=r"u\[7\]"):
        hbn.HysteresisModel.fit(u, d["x"], d["y"])
    x = d["x"].copy()
    x[7] = np.inf
    with pytest.raises(ValueError, match=r"x\[7\]"):
        hbn.HysteresisModel.fit(d["u"], x, d["y"])
    # NaN in x marks a sample the camera did not see; a state never seen is an error.
    with pytest.raises(hbn.DataError, match="NaN at every sample"):
        hbn.HysteresisModel.fit(d["u"], np.full_like(d["x"], np.nan), d["y"])
    with pytest.raises(hbn.ConfigError, match="kernel"):
        hbn.HysteresisModel.fit(d["u"], d["x"], d["y"], kernel="nope")
    with pytest.raises(ValueError, match="rate_hz"):
        hbn.HysteresisModel.fit(d["u"], d["x"], d["y"], rate_hz=-1.0)


def test_estimate_bad_inputs(trained):
    model, _, test = trained
    with pytest.raises(ValueError, match="equal lengths"):
        model.estimate(test["u"], test["y"][:-1])
    with pytest.raises(ValueError, match="unknown mode"):
        model.estimate(test["u"], test["y"], mode="kalman")


def test_simulate_bad_inputs():
    with pytest.raises(ValueError, match="unknown system"):
        hbn.simulate("no-such-system", 10)
    with pytest.raises(ValueError, match="noise_gain"):
        hbn.simulate("duhem", 10, noise_gain=-1.0)


def test_file_errors(tmp_path):
    missing = tmp_path / "missing.hbn"
    with pytest.raises(hbn.HbnFileNotFoundError, match="missing.hbn"):
        hbn.HysteresisModel.load(missing)
    with pytest.raises(FileNotFoundError):
        hbn.GaussianProcess.load(missing)
    with pytest.raises(FileNotFoundError):
        hbn.read_mcap(tmp_path / "missing.mcap", {"u": "/u.data"})
    with pytest.raises(OSError):
        hbn.HysteresisModel.load(tmp_path)  # a directory
    bad = tmp_path / "bad.hbn"
    bad.write_text('{"format": "something-else", "version": 1}')
    with pytest.raises(hbn.ModelFileError, match="not an hbn model"):
        hbn.HysteresisModel.load(bad)
    bad.write_text("hello")
    with pytest.raises(ValueError, match="not an hbn model"):
        hbn.HysteresisModel.load(bad)
    bad.write_bytes(b"\x00\xff\xfe binary")
    with pytest.raises(ValueError, match="not an hbn model"):
        hbn.HysteresisModel.load(bad)
    bad.write_text('{"format": "hbn-model", "version": 99, "model": {}}')
    with pytest.raises(ValueError, match="version 99"):
        hbn.HysteresisModel.load(bad)
    with pytest.raises(ValueError, match="not an hbn GP|not a JSON"):
        hbn.GaussianProcess.load(bad)
    notmcap = tmp_path / "x.mcap"
    notmcap.write_text("not an mcap")
    with pytest.raises(hbn.DataError, match="MCAP"):
        hbn.read_mcap(notmcap, {"u": "/u.data"})
    with pytest.raises(ValueError):
        hbn.read_mcap(notmcap, {})
