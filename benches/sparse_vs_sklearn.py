"""The sparse GP on every sample against scikit-learn's exact GP on a subset, in one run.

hbn's sparse GP (``n_inducing=m``) fits n = 50,000 samples (4 inputs); scikit-learn's exact
GP (ARD SE + white noise, the usual recipe) fits 2,000 of them. Both use one optimiser start
and standardise y. Prints each fit's wall time, the ratio, and each model's RMSE on 5,000
held-out samples (so the speed is not bought with accuracy).

    pip install ./hbn-py scikit-learn
    python3 benches/sparse_vs_sklearn.py [--n 50000] [--n-sklearn 2000] [--m 128]
"""
import argparse
import time

import numpy as np
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel

import hbn


def data(n, d, seed):
    rng = np.random.default_rng(seed)
    X = rng.uniform(-2.0, 2.0, size=(n, d))
    f = sum(np.sin(X[:, j] * (0.5 + 0.4 * j)) for j in range(d))
    return X, f + 0.1 * rng.standard_normal(n), f


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=50_000)
    ap.add_argument("--n-sklearn", type=int, default=2_000)
    ap.add_argument("--m", type=int, default=128)
    args = ap.parse_args()
    d = 4
    X, y, _ = data(args.n, d, 7)
    Xt, _, ft = data(5_000, d, 8)

    t = time.perf_counter()
    ours = hbn.GaussianProcess(kernel="se-ard", n_inducing=args.m, n_starts=1).fit(X, y)
    t_ours = time.perf_counter() - t
    rmse_ours = float(np.sqrt(np.mean((ours.predict(Xt) - ft) ** 2)))

    k = args.n_sklearn
    kernel = ConstantKernel(1.0) * RBF(np.ones(d)) + WhiteKernel(0.1)
    sk = GaussianProcessRegressor(kernel=kernel, normalize_y=True, random_state=0)
    t = time.perf_counter()
    sk.fit(X[:k], y[:k])
    t_sk = time.perf_counter() - t
    rmse_sk = float(np.sqrt(np.mean((sk.predict(Xt) - ft) ** 2)))

    print(f"hbn sparse GP, m = {args.m}, n = {args.n}: {t_ours:.2f} s, held-out RMSE {rmse_ours:.4f}")
    print(f"scikit-learn exact GP, n = {k}: {t_sk:.2f} s, held-out RMSE {rmse_sk:.4f}")
    print(f"ratio (scikit-learn time / hbn time): {t_sk / t_ours:.2f}x")


if __name__ == "__main__":
    main()
