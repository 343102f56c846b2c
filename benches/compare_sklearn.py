"""hbn against scikit-learn fitting one GP on the same data, in the same run.

n = 1000 and 2000 points, 4 inputs, SE-ARD plus noise, the same number of optimiser starts,
both standardising y. Prints each library's median wall time, the ratio, and the log marginal
likelihood each reached (on standardised targets; higher is better). hbn's side is the
harness program ``fit_timing`` (``benches/harness``), built here if it is missing.

    python3 benches/compare_sklearn.py [--starts 1] [--repeats 3] [--sizes 1000,2000]

``benches/report.py`` calls :func:`compare` for ``docs/performance.md``.
"""
import argparse
import json
import os
import pathlib
import subprocess
import tempfile
import time
from typing import Dict, List, Sequence

import numpy as np
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel

ROOT = pathlib.Path(__file__).resolve().parents[1]


def data(n, d, seed):
    """``n`` inputs uniform in [-2, 2]^d and a smooth target with noise of standard deviation 0.1."""
    rng = np.random.default_rng(seed)
    X = rng.uniform(-2.0, 2.0, size=(n, d))
    y = sum(np.sin(X[:, j] * (0.5 + 0.4 * j)) for j in range(d)) + 0.1 * rng.standard_normal(n)
    return X, y


def harness_exe(name: str) -> pathlib.Path:
    """A program of ``benches/harness`` in the release target directory, built if missing."""
    target = os.environ.get("CARGO_TARGET_DIR", str(ROOT / "target"))
    exe = pathlib.Path(target) / "release" / name
    if not exe.exists():
        subprocess.run(["cargo", "build", "--release", "-q", "-p", "hbn-harness", "--bin", name], cwd=ROOT, check=True)
    return exe


def compare(sizes: Sequence[int] = (1000, 2000), starts: int = 1, repeats: int = 3) -> List[Dict[str, float]]:
    """One row per size: ``n``, ``hbn_seconds`` and ``sklearn_seconds`` (medians over
    ``repeats`` fits), ``speedup`` (scikit-learn time / hbn time), ``hbn_lml``, ``sklearn_lml``."""
    exe = harness_exe("fit_timing")
    rows = []
    for n in sizes:
        d = 4
        X, y = data(n, d, 7)
        with tempfile.TemporaryDirectory(prefix="hbn-fit-timing-") as tmp:
            path = pathlib.Path(tmp) / "data.json"
            path.write_text(json.dumps({"x": X.ravel().tolist(), "y": y.tolist(), "d": d}))
            cmd = [str(exe), str(path), "--starts", str(starts), "--repeats", str(repeats)]
            ours = json.loads(subprocess.run(cmd, capture_output=True, text=True, check=True).stdout)
        times, lml = [], None
        for _ in range(repeats):
            kernel = ConstantKernel(1.0) * RBF(np.ones(d)) + WhiteKernel(0.1)
            gp = GaussianProcessRegressor(kernel=kernel, normalize_y=True, n_restarts_optimizer=starts - 1, random_state=0)
            t = time.perf_counter()
            gp.fit(X, y)
            times.append(time.perf_counter() - t)
            lml = gp.log_marginal_likelihood_value_
        sk = float(np.median(times))
        rows.append({
            "n": n,
            "hbn_seconds": ours["seconds_median"],
            "sklearn_seconds": sk,
            "speedup": sk / ours["seconds_median"],
            "hbn_lml": ours["lml"],
            "sklearn_lml": float(lml),
        })  # fmt: skip
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--starts", type=int, default=1, help="optimiser starts for both libraries")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--sizes", default="1000,2000")
    args = ap.parse_args()
    rows = compare([int(s) for s in args.sizes.split(",")], args.starts, args.repeats)
    print("| n | hbn fit (s) | scikit-learn fit (s) | speed-up | hbn LML | scikit-learn LML |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['n']} | {r['hbn_seconds']:.3f} | {r['sklearn_seconds']:.3f} | {r['speedup']:.1f}x | {r['hbn_lml']:.2f} | {r['sklearn_lml']:.2f} |")


if __name__ == "__main__":
    main()
