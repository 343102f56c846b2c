"""Models travel: a pickled model holds its model file and estimates bit for bit like the
original, so process pools and Dask clusters can train and carry them."""

import concurrent.futures
import copy
import multiprocessing
import pickle

import numpy as np
import pytest

import hbn

QUICK = dict(max_points=80, n_starts=1, max_iters=40)


@pytest.fixture(scope="module")
def models():
    """An exact model (the default choice on its data) and a sparse one, with a test run."""
    train = hbn.simulate("bouc-wen", 400, seed=1, noise_gain=1.0)
    exact = hbn.HysteresisModel.fit(train["u"], train["x"], train["y"], **QUICK)
    sparse = hbn.HysteresisModel.fit(
        train["u"], train["x"], train["y"], n_inducing=16, lags=[1.0], **QUICK
    )
    assert sparse.transition.is_sparse
    test = hbn.simulate("bouc-wen", 300, seed=2, noise_gain=1.0)
    return [exact, sparse], test


def assert_same_estimates(a, b, test):
    for mode in hbn.MODES:
        ea = a.estimate(test["u"], test["y"], mode=mode).to_dict()
        eb = b.estimate(test["u"], test["y"], mode=mode).to_dict()
        for k in ea:
            np.testing.assert_array_equal(ea[k], eb[k], err_msg=f"{mode} {k}")
    fa, fb = a.filter(), b.filter()
    for u, y in zip(test["u"][:50], test["y"][:50]):
        oa, ob = fa.step(u, y), fb.step(u, y)
        assert (oa.x, oa.x_std, oa.flags) == (ob.x, ob.x_std, ob.flags)


@pytest.mark.parametrize("protocol", [2, pickle.HIGHEST_PROTOCOL])
def test_a_pickled_model_estimates_bit_for_bit(models, protocol):
    ms, test = models
    for m in ms:
        back = pickle.loads(pickle.dumps(m, protocol=protocol))
        assert isinstance(back, hbn.HysteresisModel)
        assert back.to_bytes() == m.to_bytes()
        assert back.params == m.params and back.default_mode == m.default_mode
        assert_same_estimates(m, back, test)
        assert_same_estimates(m, copy.deepcopy(m), test)


def test_a_pickle_holds_the_model_file(models, tmp_path):
    m = models[0][0]
    path = tmp_path / "model.hbn"
    m.save(path)
    data = path.read_bytes()
    assert m.to_bytes() == data
    assert data in pickle.dumps(m)
    assert hbn.HysteresisModel.from_bytes(data).to_bytes() == data
    with pytest.raises(hbn.ModelFileError, match="not an hbn model"):
        hbn.HysteresisModel.from_bytes(b"\xff\xfe not a model")


def test_gaussian_processes_and_estimates_pickle(models):
    ms, test = models
    X = np.linspace(0, 5, 60)
    for gp in (hbn.GaussianProcess().fit(X, np.sin(X)), ms[1].transition, hbn.GaussianProcess()):
        back = pickle.loads(pickle.dumps(gp))
        assert back.kernel == gp.kernel and back.n_inducing == gp.n_inducing
        if gp._core is not None:
            Xq = np.zeros((3, gp.n_features_in_)) + 0.5
            np.testing.assert_array_equal(back.predict(Xq), gp.predict(Xq))
    est = ms[0].estimate(test["u"], test["y"])
    back = pickle.loads(pickle.dumps(est))
    assert back.mode == est.mode
    for k, v in est.to_dict().items():
        np.testing.assert_array_equal(getattr(back, k), v)


def _train(seed):
    d = hbn.simulate("duhem", 300, seed=seed, noise_gain=1.0)
    return hbn.HysteresisModel.fit(d["u"], d["x"], d["y"], seed=seed, **QUICK)


def test_process_pools_train_and_return_models():
    test = hbn.simulate("duhem", 200, seed=9, noise_gain=1.0)
    ctx = multiprocessing.get_context("spawn")
    with concurrent.futures.ProcessPoolExecutor(max_workers=2, mp_context=ctx) as pool:
        remote = list(pool.map(_train, [1, 2]))
    for seed, m in zip([1, 2], remote):
        local = _train(seed)
        assert m.to_bytes() == local.to_bytes()
        assert_same_estimates(local, m, test)


def test_a_dask_cluster_trains_a_fleet_and_returns_the_models():
    """A lab calibrating several robots at once: each robot's runs are trained on a worker of a
    dask.distributed cluster (two worker processes here) and the models come back."""
    distributed = pytest.importorskip(
        "dask.distributed", reason="dask[distributed] is a test-only dependency: not installed"
    )
    fleet = {f"robot-{s}": hbn.simulate("duhem", 300, seed=s, noise_gain=1.0) for s in (1, 2, 3)}
    test = hbn.simulate("duhem", 200, seed=9, noise_gain=1.0)
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster, distributed.Client(cluster) as client:
        futures = {
            name: client.submit(
                hbn.HysteresisModel.fit, d["u"], d["x"], d["y"], seed=3, **QUICK, pure=False
            )
            for name, d in fleet.items()
        }
        models = client.gather(futures)
        # And back to the workers: a model goes to an estimation task on the cluster.
        estimate = client.submit(hbn.HysteresisModel.estimate, models["robot-2"], test["u"], test["y"])
        remote_estimate = estimate.result()
    for name, d in fleet.items():
        local = hbn.HysteresisModel.fit(d["u"], d["x"], d["y"], seed=3, **QUICK)
        assert isinstance(models[name], hbn.HysteresisModel)
        assert models[name].to_bytes() == local.to_bytes(), name
        assert_same_estimates(local, models[name], test)
    here = models["robot-2"].estimate(test["u"], test["y"])
    np.testing.assert_array_equal(remote_estimate.x, here.x)
    assert remote_estimate.score(test["x"]) == here.score(test["x"])
