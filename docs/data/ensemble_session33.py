"""Session 33: would averaging the candidates' filters beat choosing one? (issue 10; dropped)

Per run (design seeds 1-3, noise gains 0 and 1, the six simulators; the grid's protocol: three
1000-sample training logs with input seed S and noise seeds 10S+1..3, a test log with input
seed S+1 and noise seed 10S+11), four models trained with `hbn train --seed S` on the three
training logs: the default (`def`), and each of its three candidates trained alone and tuned
on its own held-out blocks: `--inducing exact --lags none` (`ex`), `--inducing 64 --lags
none` (`sp`), `--inducing 64 --lags 1` (`lg`). Each estimated the test log
(`hbn estimate --model M --log test.mcap --csv M.csv`, its default mode). The shell loop:

    for k in 1 2 3; do hbn -q simulate --system SYS --steps 1000 --input-seed S \
        --seed $((10*S+k)) --noise-gain G --out train$k.mcap; done
    hbn -q simulate --system SYS --steps 1000 --input-seed $((S+1)) --seed $((10*S+11)) \
        --noise-gain G --out test.mcap

This script then scores, against the test log's recorded x, the default, each candidate, the
best candidate on the test log (an oracle, not a method), and three mixtures of the
candidates' Gaussian estimates (moment-matched: mean of the means, mean variance plus the
spread of the means): equal weights of all three (`avg3`), the two with the lowest held-out
nRMSE in the default's validation table (`top2`), and weights 1/nRMSE^2 from that table
(`invnr2`). It prints the per-cell ratio to the default (geometric mean over the seeds),
2-sigma coverage and mean NEES, and writes every run's nRMSE as JSON.

    target/py-test-venv/bin/python docs/data/ensemble_session33.py RUNS_DIR OUT.json

RUNS_DIR holds one directory `SYS-G-S` per run with the logs, `def.json` (the default's
`hbn train --json`) and `{def,ex,sp,lg}.csv`. Needs numpy and the hbn wheel (to read MCAP).
"""
import glob
import json
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "benches", "baselines"))
import common  # noqa: E402

PATHS = {"u": "/input.data", "x": "/state.data", "y": "/sensor.data"}
CANDIDATES = ["ex", "sp", "lg"]  # the order of the default's validation table


def load(d, m):
    a = np.genfromtxt(os.path.join(d, m + ".csv"), delimiter=",", names=True, dtype=None, encoding=None)
    return np.asarray(a["x"], float), np.asarray(a["x_std"], float)


def mix(parts, w=None):
    xs = np.array([p[0] for p in parts])
    ss = np.array([p[1] for p in parts])
    w = np.full(len(parts), 1.0 / len(parts)) if w is None else np.asarray(w) / np.sum(w)
    m = np.tensordot(w, xs, 1)
    return m, np.sqrt(np.tensordot(w, ss**2 + (xs - m) ** 2, 1))


def main(runs_dir, out_path):
    cells, runs = {}, []
    for d in sorted(glob.glob(os.path.join(runs_dir, "*"))):
        if not all(os.path.exists(os.path.join(d, m + ".csv")) for m in ["def"] + CANDIDATES):
            continue
        system, gain, seed = os.path.basename(d).rsplit("-", 2)
        test = common.read_log(os.path.join(d, "test.mcap"), PATHS)
        est = {m: load(d, m) for m in ["def"] + CANDIDATES}
        table = json.load(open(os.path.join(d, "def.json")))["filter"]["validation"]["candidates"]
        held_nrmse = [c["scored"][1]["nrmse"] for c in table]
        order = np.argsort(held_nrmse)
        test_nrmse = {m: common.nrmse(est[m][0], test.x) for m in CANDIDATES}
        methods = {
            "default": est["def"],
            "oracle": est[min(CANDIDATES, key=test_nrmse.get)],
            "avg3": mix([est[m] for m in CANDIDATES]),
            "top2": mix([est[CANDIDATES[i]] for i in order[:2]]),
            "invnr2": mix([est[m] for m in CANDIDATES], [1.0 / r**2 for r in held_nrmse]),
            **{m: est[m] for m in CANDIDATES},
        }
        scores = {k: common.score(x, s, test.x) for k, (x, s) in methods.items()}
        cells.setdefault((system, float(gain)), []).append(scores)
        runs.append({"system": system, "gain": float(gain), "seed": int(seed), "held_out_nrmse": held_nrmse,
                     "nrmse": {k: v["nrmse"] for k, v in scores.items()}})
    names = ["default", "oracle", "avg3", "top2", "invnr2"] + CANDIDATES
    print("| system | gain | runs | " + " | ".join(f"{n} (ratio, cov2, NEES)" for n in names) + " |")
    print("|---" * (len(names) + 3) + "|")
    logs = {n: [] for n in names}
    for (system, gain), rs in sorted(cells.items()):
        base = np.array([r["default"]["nrmse"] for r in rs])
        row = []
        for n in names:
            v = np.array([r[n]["nrmse"] for r in rs])
            logs[n] += list(np.log(v / base))
            cov = np.mean([r[n]["coverage_2sigma"] for r in rs])
            nees = np.mean([r[n]["mean_nees"] for r in rs])
            row.append(f"{math.exp(np.mean(np.log(v / base))):.3f}, {cov:.2f}, {nees:.1f}")
        print(f"| {system} | {gain:g} | {len(rs)} | " + " | ".join(row) + " |")
    print("\nGeometric mean of per-run ratios to the default: "
          + ", ".join(f"{n} {math.exp(np.mean(logs[n])):.3f}" for n in names))
    with open(out_path, "w") as f:
        json.dump(runs, f, indent=0)


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])
