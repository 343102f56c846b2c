"""A state measured at some samples only (NaN elsewhere) trains by expectation-maximisation."""

import numpy as np
import pytest

import hbn


def _filmed(x, every):
    """The state with NaN except at every ``every``-th sample."""
    out = np.full_like(x, np.nan)
    out[::every] = x[::every]
    return out


def test_a_state_with_gaps_trains_and_says_how_much_was_measured():
    runs = [hbn.simulate("duhem", 400, seed=s, noise_gain=1.0) for s in (1, 2)]
    xs = [_filmed(r["x"], 4) for r in runs]
    model = hbn.HysteresisModel.fit(
        [r["u"] for r in runs], xs, [r["y"] for r in runs], max_points=120, n_starts=1
    )
    latent = model.summary["latent"]
    assert latent["frames"] == sum(int(np.isfinite(x).sum()) for x in xs)
    assert latent["observed"] == pytest.approx(0.25, abs=0.01)
    assert latent["rounds"][0]["round"] == 0
    assert any("latent" in w for w in model.summary["warnings"])
    test = hbn.simulate("duhem", 300, seed=7, noise_gain=1.0)
    est = model.estimate(test["u"], test["y"])
    assert np.isfinite(est.x).all()
    nrmse = np.sqrt(np.mean((est.x - test["x"]) ** 2)) / np.ptp(test["x"])
    assert nrmse < 0.1


def test_a_fully_measured_state_trains_as_before():
    r = hbn.simulate("duhem", 300, seed=1, noise_gain=1.0)
    model = hbn.HysteresisModel.fit(r["u"], r["x"], r["y"], max_points=100, n_starts=1)
    assert model.summary.get("latent") is None


def test_a_trajectory_without_a_measured_state_is_a_data_error():
    r = hbn.simulate("duhem", 100, seed=1, noise_gain=1.0)
    with pytest.raises(hbn.DataError, match="NaN at every sample"):
        hbn.HysteresisModel.fit(r["u"], np.full(100, np.nan), r["y"], max_points=50, n_starts=1)
