"""HysteresisModel.smooth: the offline smoother returns what estimate returns, smoothed."""

import numpy as np
import pytest

import hbn
from conftest import nrmse


@pytest.mark.parametrize("mode", hbn.MODES)
def test_smoothing_beats_the_filter(trained, mode):
    model, _, test = trained
    est = model.estimate(test["u"], test["y"], mode=mode)
    smo = model.smooth(test["u"], test["y"], mode=mode)
    assert isinstance(smo, hbn.Estimate) and smo.mode == est.mode
    # Every field has the estimate's shape; the filter's diagnostics are the filter's.
    for name in ("x", "x_std", "y_pred", "innovation", "nis", "q_x", "r", "flags"):
        assert getattr(smo, name).shape == getattr(est, name).shape, name
    np.testing.assert_array_equal(smo.nis, est.nis)
    np.testing.assert_array_equal(smo.flags, est.flags)
    # The last sample has nothing after it; every other one is at least as certain.
    assert smo.x[-1] == est.x[-1] and smo.x_std[-1] == est.x_std[-1]
    assert np.all(np.isfinite(smo.x)) and np.all(smo.x_std > 0)
    assert np.all(smo.x_std <= est.x_std * (1 + 1e-9))
    assert nrmse(smo.x, test["x"]) < nrmse(est.x, test["x"])


def test_smooth_takes_columns_and_the_default_mode(trained):
    model, _, test = trained
    flat = model.smooth(test["u"], test["y"])
    assert flat.mode == model.default_mode
    cols = model.smooth(test["u"].reshape(-1, 1), test["y"].reshape(-1, 1))
    assert cols.x.shape == (len(test["u"]), 1)
    np.testing.assert_array_equal(cols.x[:, 0], flat.x)


def test_smooth_checks_its_arguments(trained):
    model, _, test = trained
    with pytest.raises(ValueError, match="equal lengths"):
        model.smooth(test["u"], test["y"][:-1])
    with pytest.raises(ValueError, match="unknown mode"):
        model.smooth(test["u"], test["y"], mode="kalman")
