"""hbn.Explorer and hbn.Simulator: bounds and increment bound kept, determinism, a working
model, planning, every bad keyword named, NaN rejected, defaults from the library, the
simulator equal to hbn.simulate, and the worked example."""

import math

import numpy as np
import pytest

import hbn

QUICK = dict(random_samples=40, max_points=60, n_starts=1, max_iters=40, validation=0.0)


def drive(explorer, system="duhem", steps=200, seed=1):
    robot = hbn.Simulator(system, seed=seed, noise_gain=1.0)
    applied = []
    for _ in range(steps):
        u = explorer.propose()
        x, y = robot.step(u)
        explorer.observe(u, x, y)
        applied.append(u)
    return np.asarray(applied)


@pytest.mark.parametrize(
    "lo,hi,eta,strategy,criterion",
    [
        (0.3, 0.45, 0.05, "ramps", "variance"),
        (0.3, 0.45, 0.05, "steps", "variance"),
        (0.0, 1.0, 0.02, "ramps", "variance"),
        (0.0, 1.0, 0.02, "ramps", "reduction"),
    ],
)
def test_proposals_keep_the_bounds_and_the_increment_bound(lo, hi, eta, strategy, criterion):
    e = hbn.Explorer(
        lo, hi, eta, strategy=strategy, criterion=criterion, alpha_start=1.0, alpha_end=1.0,
        **QUICK,
    )
    u = drive(e, "bouc-wen", 300)
    assert e.phase == "seeking" and e.alpha == 1.0
    assert np.all((u >= lo) & (u <= hi))
    assert np.all(np.abs(np.diff(u)) <= eta)
    assert u[0] == lo  # u_start defaults to u_min
    assert e.warnings == []


def test_equal_seeds_give_equal_proposals():
    a = drive(hbn.Explorer(0.0, 1.0, 0.02, seed=5, **QUICK), steps=120)
    b = drive(hbn.Explorer(0.0, 1.0, 0.02, seed=5, **QUICK), steps=120)
    c = drive(hbn.Explorer(0.0, 1.0, 0.02, seed=6, **QUICK), steps=120)
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_with_a_lag_refits_run_beside_the_loop_and_stay_deterministic():
    # The first GP starts fitting when the random phase ends and is used a refit's lag (10
    # samples, as refit_every) later, not the whole lag.
    e = hbn.Explorer(0.0, 1.0, 0.02, seed=5, lag=25, **QUICK)
    assert e.settings["lag"] == 25
    drive(e, steps=QUICK["random_samples"] + 9)
    assert e.phase == "random"
    drive(e, steps=1)
    assert e.phase == "seeking"
    a = drive(hbn.Explorer(0.0, 1.0, 0.02, seed=5, lag=25, **QUICK), steps=160)
    b = drive(hbn.Explorer(0.0, 1.0, 0.02, seed=5, lag=25, **QUICK), steps=160)
    assert np.array_equal(a, b)


def test_the_model_estimates_and_the_runs_are_kept():
    e = hbn.Explorer(0.0, 1.0, 0.02, **QUICK)
    drive(e, steps=150)
    e.start_run()
    assert e.propose() == 0.0
    drive(e, steps=60, seed=2)
    assert e.n_observed == 210
    assert [len(r["u"]) for r in e.runs] == [150, 60]
    model = e.model()
    assert isinstance(model, hbn.HysteresisModel)
    assert model.summary["trajectories"] == 2
    te = hbn.simulate("duhem", 300, seed=9, noise_gain=1.0)
    est = model.estimate(te["u"], te["y"])
    assert np.all(np.isfinite(est.x)) and est.score(te["x"])["nrmse"] < 0.3


def test_a_plan_keeps_the_bounds_and_leaves_the_explorer_unchanged():
    e = hbn.Explorer(0.0, 1.0, 0.02, **QUICK)
    last = drive(e, steps=60)[-1]
    u, x = e.plan(300)
    assert e.n_observed == 60
    assert u.shape == x.shape == (300,)
    full = np.concatenate([[last], u])
    assert np.all((u >= 0.0) & (u <= 1.0)) and np.all(np.abs(np.diff(full)) <= 0.02)
    assert np.all(np.isfinite(x))
    assert np.array_equal(e.plan(300)[0], u)


@pytest.mark.parametrize(
    "kwargs,keyword",
    [
        (dict(u_min=float("nan")), "u_min"),
        (dict(u_max=0.0), "u_max"),
        (dict(max_step=0.0), "max_step"),
        (dict(max_step="big"), "max_step"),
        (dict(u_start=2.0), "u_start"),
        (dict(random_samples=3), "random_samples"),
        (dict(random_samples=-1), "random_samples"),
        (dict(alpha_start=-0.5), "alpha_start"),
        (dict(alpha_end=1.5), "alpha_end"),
        (dict(refit_every=0), "refit_every"),
        (dict(optimize_every=0), "optimize_every"),
        (dict(candidates=1), "candidates"),
        (dict(horizon=0), "horizon"),
        (dict(pool=1), "pool"),
        (dict(pool=-2), "pool"),
        (dict(lag=-1), "lag"),
        (dict(strategy="zigzag"), "strategy"),
        (dict(criterion="entropy"), "criterion"),
        (dict(max_points=1), "max_points"),
        (dict(rate_hz=-1.0), "rate_hz"),
    ],
)
def test_every_bad_keyword_is_named(kwargs, keyword):
    args = dict(u_min=0.0, u_max=1.0, max_step=0.02)
    args.update(kwargs)
    with pytest.raises(hbn.ConfigError) as e:
        hbn.Explorer(**args)
    assert e.value.keyword == keyword, str(e.value)


def test_an_unknown_keyword_is_a_type_error():
    with pytest.raises(TypeError):
        hbn.Explorer(0.0, 1.0, 0.02, no_such_thing=1)


def test_a_nan_observation_is_rejected_and_not_recorded():
    e = hbn.Explorer(0.0, 1.0, 0.02)
    e.observe(0.0, 0.1, 0.2)
    with pytest.raises(hbn.DataError, match="x is NaN"):
        e.observe(0.01, math.nan, 0.2)
    assert e.n_observed == 1


def test_defaults_come_from_the_library():
    d = hbn.default_explore_params()
    assert {"u_min", "u_max", "max_step"}.isdisjoint(d)
    s = hbn.Explorer(0.0, 1.0, 0.02).settings
    for k, v in d.items():
        assert s[k] == v, k
    assert d["strategy"] == "ramps" and d["horizon"] == 50 and d["random_samples"] == 200
    assert d["pool"] == 8
    assert hbn.Explorer(0.0, 1.0, 0.02, pool=3).settings["pool"] == 3
    assert d["lag"] == 0
    assert d["criterion"] == "reduction"


def test_the_criterion_reaches_the_engine():
    # Same seed, same robot: the seeking ramps differ once the criterion scores them.
    seeking = dict(seed=3, alpha_start=1.0, alpha_end=1.0, **QUICK)
    a = drive(hbn.Explorer(0.0, 1.0, 0.02, criterion="variance", **seeking), steps=300)
    b = drive(hbn.Explorer(0.0, 1.0, 0.02, criterion="reduction", **seeking), steps=300)
    n = QUICK["random_samples"]
    assert np.array_equal(a[:n], b[:n]) and not np.array_equal(a, b)
    assert hbn.Explorer(0.0, 1.0, 0.02, criterion="variance").settings["criterion"] == "variance"


def test_the_simulator_gives_what_simulate_gives():
    d = hbn.simulate("soft-actuator", 300, seed=4, noise_gain=1.0)
    robot = hbn.Simulator("soft-actuator", seed=4, noise_gain=1.0)
    xy = np.array([robot.step(u) for u in d["u"]])
    assert np.array_equal(xy[:, 0], d["x"]) and np.array_equal(xy[:, 1], d["y"])
    assert robot.steps == 300
    with pytest.raises(hbn.DataError):
        robot.step(float("inf"))
    with pytest.raises(hbn.DataError):
        robot.step(9.0)
    assert robot.steps == 300
    with pytest.raises(hbn.ConfigError) as e:
        hbn.Simulator("no-such-system")
    assert e.value.keyword == "system"
