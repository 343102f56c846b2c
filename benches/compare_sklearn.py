"""hbn vs scikit-learn GP fitting on the same data, in the same run (issue: GP engine).

n = 1000 and 2000 points, 4 inputs, ARD SE + noise, the same number of optimiser starts,
both standardising y. Prints each library's median wall time, the ratio, and the log
marginal likelihood each reached (on standardised targets; higher is better).

    cargo build --release -p hbn-gp --example fit_timing
    python3 benches/compare_sklearn.py [--starts 1] [--repeats 3]
"""
import argparse
import json
import os
import pathlib
import subprocess
import tempfile
import time

import numpy as np
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel

ROOT = pathlib.Path(__file__).resolve().parents[1]


def data(n, d, seed):
    rng = np.random.default_rng(seed)
    X = rng.uniform(-2.0, 2.0, size=(n, d))
    y = sum(np.sin(X[:, j] * (0.5 + 0.4 * j)) for j in range(d)) + 0.1 * rng.standard_normal(n)
    return X, y


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--starts", type=int, default=1, help="optimiser starts for both libraries")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--sizes", default="1000,2000")
    args = ap.parse_args()
    target = os.environ.get("CARGO_TARGET_DIR", str(ROOT / "target"))
    exe = pathlib.Path(target) / "release" / "examples" / "fit_timing"
    if not exe.exists():
        subprocess.run(["cargo", "build", "--release", "-q", "-p", "hbn-gp", "--example", "fit_timing"], cwd=ROOT, check=True)
    rows = []
    for n in [int(s) for s in args.sizes.split(",")]:
        d = 4
        X, y = data(n, d, 7)
        with tempfile.NamedTemporaryFile("w", suffix=".json", delete=False) as f:
            json.dump({"x": X.ravel().tolist(), "y": y.tolist(), "d": d}, f)
            path = f.name
        out = subprocess.run([str(exe), path, str(args.starts), str(args.repeats)], capture_output=True, text=True, check=True)
        ours = json.loads(out.stdout)
        os.unlink(path)
        times, lml = [], None
        for _ in range(args.repeats):
            kernel = ConstantKernel(1.0) * RBF(np.ones(d)) + WhiteKernel(0.1)
            gp = GaussianProcessRegressor(kernel=kernel, normalize_y=True, n_restarts_optimizer=args.starts - 1, random_state=0)
            t = time.perf_counter()
            gp.fit(X, y)
            times.append(time.perf_counter() - t)
            lml = gp.log_marginal_likelihood_value_
        sk = float(np.median(times))
        rows.append((n, ours["seconds_median"], sk, sk / ours["seconds_median"], ours["lml"], lml))
    print(f"| n | hbn fit (s) | scikit-learn fit (s) | speed-up | hbn LML | scikit-learn LML |")
    print("|---|---|---|---|---|---|")
    for n, a, b, r, la, lb in rows:
        print(f"| {n} | {a:.3f} | {b:.3f} | {r:.1f}x | {la:.2f} | {lb:.2f} |")


if __name__ == "__main__":
    main()
