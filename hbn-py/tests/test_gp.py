"""GaussianProcess: scikit-learn parity at fixed hyperparameters, gradients, persistence."""

import numpy as np
import pytest

import hbn

sklearn = pytest.importorskip("sklearn")
from sklearn.gaussian_process import GaussianProcessRegressor  # noqa: E402
from sklearn.gaussian_process.kernels import RBF, ConstantKernel  # noqa: E402


def _data(n, d, seed):
    rng = np.random.default_rng(seed)
    X = rng.uniform(-2.0, 2.0, size=(n, d))
    y = np.sin(X).sum(axis=1) + 0.3 * X[:, 0] ** 2 + 0.05 * rng.standard_normal(n)
    Xs = rng.uniform(-2.5, 2.5, size=(15, d))
    ls = rng.uniform(0.5, 2.0, size=d)
    return X, y, Xs, ls, float(rng.uniform(0.5, 3.0)), float(rng.uniform(1e-3, 0.1))


@pytest.mark.parametrize("n,d,seed", [(30, 4, 0), (60, 3, 1), (25, 1, 2), (80, 2, 3)])
def test_sklearn_parity_fixed_hyperparameters(n, d, seed):
    X, y, Xs, ls, sf2, noise = _data(n, d, seed)
    sk = GaussianProcessRegressor(
        kernel=ConstantKernel(sf2, "fixed") * RBF(ls, "fixed"),
        alpha=noise,
        optimizer=None,
        normalize_y=False,
    ).fit(X, y)
    m_sk, s_sk = sk.predict(Xs, return_std=True)
    gp = hbn.GaussianProcess(
        kernel="se-ard",
        lengthscales=ls,
        signal_variance=sf2,
        noise_variance=noise,
        optimize=False,
        normalize=False,
    ).fit(X, y)
    m, s = gp.predict(Xs, return_std=True)
    np.testing.assert_allclose(m, m_sk, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(s, s_sk, rtol=1e-6, atol=1e-9)
    lml = gp.log_marginal_likelihood()
    assert abs(lml - sk.log_marginal_likelihood_value_) <= 1e-6 * abs(sk.log_marginal_likelihood_value_)
    # Given hyperparameters are used exactly.
    hp = gp.hyperparameters
    np.testing.assert_allclose(hp["lengthscales"], ls, rtol=1e-12)
    assert hp["signal_variance"] == pytest.approx(sf2, rel=1e-12)
    assert hp["noise_variance"] == pytest.approx(noise, rel=1e-12)
    assert hp["theta"].shape == (1 + d,)
    assert gp.n_support == n


def test_normalize_and_optimize_paths_are_finite():
    X, y, Xs, ls, sf2, noise = _data(60, 3, 7)
    for kwargs in (
        dict(lengthscales=ls, signal_variance=sf2, noise_variance=noise, optimize=False, normalize=True),
        dict(optimize=True, normalize=True, n_starts=2),
        dict(optimize=True, normalize=False, n_starts=1),
    ):
        gp = hbn.GaussianProcess(**kwargs).fit(X, y)
        m, s = gp.predict(Xs, return_std=True)
        assert np.all(np.isfinite(m)) and np.all(np.isfinite(s)) and np.all(s >= 0)
        assert np.isfinite(gp.log_marginal_likelihood())
    # The optimised model fits the training data well.
    assert np.sqrt(np.mean((gp.predict(X) - y) ** 2)) < 0.2


def test_optimized_normalized_prediction_close_to_sklearn_optimum():
    X, y, Xs, _, _, _ = _data(50, 2, 11)
    gp = hbn.GaussianProcess(n_starts=3).fit(X, y)
    hp = gp.hyperparameters
    sk = GaussianProcessRegressor(
        kernel=ConstantKernel(hp["signal_variance"], "fixed") * RBF(hp["lengthscales"], "fixed"),
        alpha=hp["noise_variance"],
        optimizer=None,
        normalize_y=False,
    ).fit(X, y - y.mean())
    # Standardised fit = raw-unit GP around the target mean, so predictions agree closely.
    np.testing.assert_allclose(gp.predict(Xs), sk.predict(Xs) + y.mean(), rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize(
    "kernel,optimize",
    [("se", False), ("se-ard", False), ("se-ard", True), ("matern52", False),
     ("thesis", False), ("thesis", True)],
)
def test_gradient_matches_finite_differences(kernel, optimize):
    rng = np.random.default_rng(5)
    X = rng.uniform(-1.0, 1.0, size=(40, 3))
    y = np.sin(2 * X[:, 0]) + X[:, 1] * X[:, 2]
    gp = hbn.GaussianProcess(
        kernel=kernel, optimize=optimize, noise_variance=None if optimize else 1e-2,
        n_starts=1, max_iters=50,
    ).fit(X, y)
    Xs = rng.uniform(-0.8, 0.8, size=(6, 3))
    mean, std, grad = gp.predict(Xs, return_std=True, return_grad=True)
    assert grad.shape == (6, 3)
    m2, g2 = gp.predict(Xs, return_grad=True)
    np.testing.assert_array_equal(m2, mean)
    np.testing.assert_array_equal(g2, grad)
    h = 1e-5  # central differences: truncation ~h^2, round-off ~eps |alpha| / h
    for j in range(3):
        e = np.zeros(3)
        e[j] = h
        if kernel == "thesis":
            # The direction sign (x0 - x1) is piecewise constant: stay on one side.
            keep = np.abs(Xs[:, 0] - Xs[:, 1]) > 10 * h
        else:
            keep = np.ones(len(Xs), bool)
        fd = (gp.predict(Xs + e) - gp.predict(Xs - e)) / (2 * h)
        np.testing.assert_allclose(grad[keep, j], fd[keep], rtol=1e-4, atol=1e-5)


def test_one_dimensional_inputs_and_array_likes(tmp_path):
    x = list(np.linspace(0.0, 5.0, 30))
    y = [float(np.sin(v)) for v in x]
    gp = hbn.GaussianProcess().fit(x, y)
    assert gp.n_features_in_ == 1
    m = gp.predict([1.0, 2.0])
    assert m.shape == (2,)
    np.testing.assert_allclose(m, np.sin([1.0, 2.0]), atol=1e-2)
    assert gp.predict(np.array([[1.0], [2.0]])).shape == (2,)
    p = tmp_path / "gp.json"
    gp.save(p)
    back = hbn.GaussianProcess.load(p)
    np.testing.assert_array_equal(back.predict([1.0, 2.5]), gp.predict([1.0, 2.5]))
    assert back.log_marginal_likelihood() == gp.log_marginal_likelihood()
    assert isinstance(gp.report_, dict) and "n_support" in gp.report_


def test_subset_is_reported():
    X = np.linspace(0, 10, 300)
    gp = hbn.GaussianProcess(max_points=50, n_starts=1).fit(X, np.sin(X))
    assert gp.n_support == 50
    # Keeping a subset is reported, and is normal: not a warning.
    assert gp.report_["n_samples"] == 300 and gp.report_["subset_policy"] == "farthest-point"
    assert not any("support points" in w for w in gp.warnings_)


# ------------------------------------------------------------------------------------------------
# Sparse GP (n_inducing)
# ------------------------------------------------------------------------------------------------


def test_sparse_with_all_points_as_inducing_equals_exact():
    rng = np.random.default_rng(3)
    X = rng.uniform(-2, 2, size=(40, 2))
    y = np.sin(X).sum(axis=1) + 0.05 * rng.standard_normal(40)
    kw = dict(lengthscales=[1.2, 0.8], signal_variance=1.5, noise_variance=0.01, optimize=False)
    exact = hbn.GaussianProcess(**kw).fit(X, y)
    sparse = hbn.GaussianProcess(n_inducing=40, inducing_points=X, **kw).fit(X, y)
    assert sparse.is_sparse and not exact.is_sparse
    Xs = rng.uniform(-2, 2, size=(10, 2))
    m1, s1, g1 = exact.predict(Xs, return_std=True, return_grad=True)
    m2, s2, g2 = sparse.predict(Xs, return_std=True, return_grad=True)
    np.testing.assert_allclose(m2, m1, rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(s2, s1, rtol=1e-7, atol=1e-10)
    np.testing.assert_allclose(g2, g1, rtol=1e-7, atol=1e-9)
    assert sparse.log_marginal_likelihood() == pytest.approx(exact.log_marginal_likelihood(), rel=1e-8)


def test_sparse_learns_from_every_sample_and_bounds_the_exact_lml():
    rng = np.random.default_rng(4)
    X = rng.uniform(0, 5, size=(3000, 1))
    y = np.sin(X[:, 0]) + 0.1 * rng.standard_normal(3000)
    sparse = hbn.GaussianProcess(n_inducing=20).fit(X, y)
    # A smooth 1-D function: the greedy selection may stop before 20 points (it says so).
    assert 8 <= sparse.n_support <= 20
    if sparse.n_support < 20:
        assert any("inducing points" in w for w in sparse.warnings_)
    assert sparse.report_["n_samples"] == 3000
    assert sparse.inducing_points_.shape == (sparse.n_support, 1)
    Xt = np.linspace(0.2, 4.8, 50)[:, None]
    assert np.max(np.abs(sparse.predict(Xt) - np.sin(Xt[:, 0]))) < 0.05
    # The bound never exceeds the exact LML at the same hyperparameters.
    hp = sparse.hyperparameters
    fixed = dict(
        lengthscales=hp["lengthscales"],
        signal_variance=hp["signal_variance"],
        noise_variance=hp["noise_variance"],
        optimize=False,
    )
    small = slice(0, 400)
    b = hbn.GaussianProcess(n_inducing=20, **fixed).fit(X[small], y[small])
    e = hbn.GaussianProcess(max_points=400, **fixed).fit(X[small], y[small])
    assert b.log_marginal_likelihood() <= e.log_marginal_likelihood() + 1e-9


def test_fixed_and_learned_inducing_points():
    rng = np.random.default_rng(5)
    X = rng.uniform(-1, 1, size=(600, 2))
    y = X[:, 0] ** 2 - X[:, 1] + 0.05 * rng.standard_normal(600)
    Z = X[:6] + 0.01
    fixed = hbn.GaussianProcess(n_inducing=6, inducing_points=Z, n_starts=1).fit(X, y)
    np.testing.assert_allclose(fixed.inducing_points_, Z, rtol=1e-13, atol=1e-15)
    learned = hbn.GaussianProcess(
        n_inducing=6, inducing_points=Z, optimize_inducing=True, n_starts=1
    ).fit(X, y)
    assert not np.array_equal(learned.inducing_points_, Z)
    assert learned.log_marginal_likelihood() > fixed.log_marginal_likelihood()


def test_sparse_argument_errors():
    X = np.linspace(0, 1, 20)
    with pytest.raises(ValueError, match="n_inducing"):
        hbn.GaussianProcess(inducing_points=[[0.0]]).fit(X, X**2)
    with pytest.raises(ValueError, match="rows"):
        hbn.GaussianProcess(n_inducing=3, inducing_points=[[0.0], [1.0]]).fit(X, X**2)
    with pytest.raises(ValueError, match="n_inducing"):
        hbn.GaussianProcess(n_inducing=0).fit(X, X**2)
    with pytest.raises(ValueError, match="exact GP has no inducing"):
        _ = hbn.GaussianProcess().fit(X, X**2).inducing_points_


@pytest.mark.parametrize("n_inducing", [None, 24])
def test_linear_mean_follows_the_plane_outside_the_data(n_inducing):
    rng = np.random.default_rng(3)
    X = rng.uniform(-1, 1, size=(300, 2))
    plane = lambda Z: 2.0 * Z[:, 0] - 3.0 * Z[:, 1] + 0.5
    y = plane(X) + 0.1 * np.sin(4 * X[:, 0]) + 0.01 * rng.normal(size=300)
    far = np.array([[6.0, -4.0]])
    linear = hbn.GaussianProcess(mean="linear", n_inducing=n_inducing, n_starts=1).fit(X, y)
    constant = hbn.GaussianProcess(n_inducing=n_inducing, n_starts=1).fit(X, y)
    mean, grad = linear.predict(far, return_grad=True)
    assert abs(mean[0] - plane(far)[0]) < 1.5
    assert abs(grad[0, 1] + 3.0) < 0.1
    assert abs(constant.predict(far)[0] - plane(far)[0]) > 10.0
    with pytest.raises(hbn.ConfigError) as e:
        hbn.GaussianProcess(mean="quadratic").fit(X, y)
    assert e.value.keyword == "mean"
