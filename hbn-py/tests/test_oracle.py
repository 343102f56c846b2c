"""hbn.oracle_estimate, the floors under causal estimation and under smoothing on simulated
logs: exact on noise-free data, a calibrated posterior that uses y, the same figures as the Rust
function through the step-by-step Simulator, and errors that name what to fix."""

import numpy as np
import pytest

import hbn


def test_noise_free_logs_give_the_state_exactly():
    d = hbn.simulate("preisach", 300, seed=4)
    o = hbn.oracle_estimate("preisach", d["u"], d["x"], d["y"])
    assert np.array_equal(o["mean"], d["x"])
    assert np.all(o["std"] == 0.0)


#: The simulators with an exact floor: every one but the load system, whose disturbance propagates.
EXACT = [s for s in hbn.SYSTEMS if s != "soft-actuator-load"]


@pytest.mark.parametrize("system", EXACT)
def test_the_posterior_is_calibrated_and_beats_the_clean_state(system):
    gain = 5.0
    d = hbn.simulate(system, 600, seed=21, noise_gain=gain)
    o = hbn.oracle_estimate(system, d["u"], d["x"], d["y"], noise_gain=gain)
    err = d["x"] - o["mean"]
    nees = float(np.mean((err / o["std"]) ** 2))
    assert 0.8 < nees < 1.25, nees
    # The prior alone (the clean state, exact from u) errs by the disturbance (width 0.02 g);
    # the sensor, flat near its saturation, tells least on Bouc-Wen (0.85x the prior there).
    prior_sd = 0.02 * gain / np.sqrt(12.0)
    assert float(np.sqrt(np.mean(err**2))) < 0.93 * prior_sd


def test_a_simulator_stepped_by_hand_gives_the_same_floor():
    # A log from the step-by-step Simulator (another input, another seed) is a trajectory of
    # the same system: the oracle must accept it, and the true state must explain y there.
    sim = hbn.Simulator("duhem", seed=5, noise_gain=3.0)
    u = 0.5 + 0.4 * np.sin(np.linspace(0.0, 12.0, 400))
    xy = np.array([sim.step(float(v)) for v in u])
    o = hbn.oracle_estimate("duhem", u, xy[:, 0], xy[:, 1], noise_gain=3.0)
    assert float(np.max(np.abs(o["mean"] - xy[:, 0]))) <= 0.02 * 3.0
    assert float(np.sqrt(np.mean((o["mean"] - xy[:, 0]) ** 2))) < 0.85 * 0.06 / np.sqrt(12.0)


def test_errors_name_what_to_fix():
    d = hbn.simulate("bouc-wen", 50, seed=1, noise_gain=1.0)
    with pytest.raises(hbn.DataError, match="length"):
        hbn.oracle_estimate("bouc-wen", d["u"], d["x"], d["y"][:-1], noise_gain=1.0)
    with pytest.raises(hbn.ConfigError, match="system"):
        hbn.oracle_estimate("no-such-system", d["u"], d["x"], d["y"])
    with pytest.raises(hbn.ConfigError, match="noise_gain"):
        hbn.oracle_estimate("bouc-wen", d["u"], d["x"], d["y"], noise_gain=-1.0)
    u = d["u"].copy()
    u[3] = 7.0
    with pytest.raises(hbn.DataError, match="outside"):
        hbn.oracle_estimate("bouc-wen", u, d["x"], d["y"], noise_gain=1.0)


def test_a_propagating_disturbance_has_no_floor():
    # soft-actuator-load's disturbance enters before its dynamics: the true past states do not
    # pin the current state, so the oracle refuses it, naming the argument to change.
    assert "soft-actuator-load" in hbn.SYSTEMS
    d = hbn.simulate("soft-actuator-load", 100, seed=2, noise_gain=1.0)
    with pytest.raises(hbn.ConfigError, match="propagates") as e:
        hbn.oracle_estimate("soft-actuator-load", d["u"], d["x"], d["y"], noise_gain=1.0)
    assert e.value.keyword == "system"


def test_the_two_sided_floor_is_never_above_the_causal_one():
    # Seeing the outputs after k and the true later states can only narrow x[k]'s posterior:
    # over a log, the two-sided floor's squared error is at most the causal one's, lookahead 0
    # is the causal floor exactly, and noise-free logs give the state.
    d = hbn.simulate("duhem", 600, seed=4, noise_gain=3.0)
    causal = hbn.oracle_estimate("duhem", d["u"], d["x"], d["y"], noise_gain=3.0)
    zero = hbn.oracle_estimate("duhem", d["u"], d["x"], d["y"], noise_gain=3.0, lookahead=0)
    whole = hbn.oracle_estimate("duhem", d["u"], d["x"], d["y"], noise_gain=3.0, lookahead=None)
    some = hbn.oracle_estimate("duhem", d["u"], d["x"], d["y"], noise_gain=3.0, lookahead=20)
    assert np.array_equal(causal["mean"], zero["mean"])
    mse = lambda o: float(np.mean((o["mean"] - d["x"]) ** 2))
    assert mse(whole) <= mse(some) <= mse(causal)
    assert mse(whole) < mse(causal)
    clean = hbn.simulate("duhem", 200, seed=4)
    o = hbn.oracle_estimate("duhem", clean["u"], clean["x"], clean["y"], lookahead=None)
    assert np.array_equal(o["mean"], clean["x"])
    for bad in (-1, 2.5, True):
        with pytest.raises(hbn.ConfigError, match="lookahead") as e:
            hbn.oracle_estimate("duhem", d["u"], d["x"], d["y"], noise_gain=3.0, lookahead=bad)
        assert e.value.keyword == "lookahead"


def test_a_multi_signal_floor_uses_the_sensors():
    # The finger's disturbance propagates through the tip's lag: its floor is the posterior
    # given u and y and the simulator (a particle filter), not given the true past states.
    gain = 10.0
    d = hbn.simulate("finger", 400, seed=8, noise_gain=gain)
    o = hbn.oracle_estimate("finger", d["u"], d["x"], d["y"], noise_gain=gain, particles=300)
    assert o["mean"].shape == o["std"].shape == (400, 2)
    # Without the sensors (every output missing) the same filter is the prior.
    blind = hbn.oracle_estimate(
        "finger", d["u"], d["x"], np.full_like(d["y"], np.nan), noise_gain=gain, particles=300
    )
    for i in range(2):
        with_y = float(np.sqrt(np.mean((o["mean"][:, i] - d["x"][:, i]) ** 2)))
        without = float(np.sqrt(np.mean((blind["mean"][:, i] - d["x"][:, i]) ** 2)))
        assert with_y < 0.8 * without, (i, with_y, without)
        inside = float(np.mean(np.abs(o["mean"][:, i] - d["x"][:, i]) <= 2 * o["std"][:, i]))
        assert 0.9 <= inside <= 1.0, (i, inside)
    clean = hbn.simulate("finger", 200, seed=8)
    exact = hbn.oracle_estimate("finger", clean["u"], clean["x"], clean["y"])
    np.testing.assert_allclose(exact["mean"], clean["x"], atol=1e-12)


def test_a_multi_signal_floor_names_what_to_fix():
    d = hbn.simulate("arm", 50, seed=1, noise_gain=1.0)
    with pytest.raises(hbn.DataError, match=r"\(T, 4\)"):
        hbn.oracle_estimate("arm", d["u"], d["x"], d["y"][:, :3], noise_gain=1.0)
    with pytest.raises(hbn.DataError, match="length"):
        hbn.oracle_estimate("arm", d["u"], d["x"], d["y"][:-1], noise_gain=1.0)
    with pytest.raises(hbn.ConfigError, match="lookahead"):
        hbn.oracle_estimate("arm", d["u"], d["x"], d["y"], noise_gain=1.0, lookahead=5)
    with pytest.raises(hbn.ConfigError, match="particles"):
        hbn.oracle_estimate("arm", d["u"], d["x"], d["y"], noise_gain=1.0, particles=0)
