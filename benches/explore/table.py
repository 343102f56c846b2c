"""Summarises the CSV of `cargo run --release -p hbn-model --example explore_eval` as the
Markdown tables of docs/exploration.md: mean nRMSE per system, amount of data and method (over
seeds), the ratio to random ramps, and the smallest amount of explored data that reaches the
accuracy of random ramps on the largest amount.

Usage: python benches/explore/table.py RUNS.csv [RUNS2.csv ...]
"""
import csv
import math
import sys
from collections import defaultdict


def main(paths):
    runs = defaultdict(list)  # (system, samples, method) -> [nrmse]
    for path in paths:
        with open(path) as f:
            for row in csv.DictReader(f):
                try:
                    key = (row["system"], int(row["samples"]), row["method"])
                    runs[key].append(float(row["nrmse"]))
                except (KeyError, ValueError):
                    continue
    systems = sorted({k[0] for k in runs})
    sizes = sorted({k[1] for k in runs})
    methods = ["random-ramps", "explore-ramps", "explore-steps"]
    print("| system | samples | seeds | random ramps | explorer (ramps, default) | ratio | explorer (thesis steps) | ratio |")
    print("|---|---|---|---|---|---|---|---|")
    ratios = defaultdict(list)
    for s in systems:
        for n in sizes:
            base = runs.get((s, n, methods[0]))
            if not base:
                continue
            mb = sum(base) / len(base)
            cells = []
            for m in methods[1:]:
                v = runs.get((s, n, m))
                if v:
                    mv = sum(v) / len(v)
                    cells += [f"{mv:.4f}", f"{mv / mb:.2f}"]
                    ratios[m].append(mv / mb)
                else:
                    cells += ["", ""]
            print(f"| {s} | {n} | {len(base)} | {mb:.4f} | " + " | ".join(cells) + " |")
    for m, r in ratios.items():
        g = math.exp(sum(math.log(x) for x in r) / len(r))
        print(f"\n{m}: geometric mean ratio to random ramps {g:.2f} over {len(r)} cells; "
              f"no worse in {sum(x <= 1.0 for x in r)} of {len(r)}")
    print("\nData needed to reach the accuracy of random ramps on the most samples:")
    for s in systems:
        top = max(n for n in sizes if runs.get((s, n, methods[0])))
        target = sum(runs[(s, top, methods[0])]) / len(runs[(s, top, methods[0])])
        for m in methods[1:]:
            need = next(
                (n for n in sizes
                 if runs.get((s, n, m)) and sum(runs[(s, n, m)]) / len(runs[(s, n, m)]) <= target),
                None,
            )
            said = f"{need} samples" if need else f"more than {top}"
            print(f"- {s}, {m}: {said} (random ramps: {top} samples, nRMSE {target:.4f})")


if __name__ == "__main__":
    main(sys.argv[1:])
