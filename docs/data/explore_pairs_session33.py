"""Paired comparison of exploration methods from `explore_eval` CSV runs (session 33).

    python3 docs/data/explore_pairs_session33.py SEEDS FILE.csv [FILE.csv ...]

SEEDS: comma-separated seeds to include. `explore-ramps-error` is the error-seeking criterion
tried in session 33 and removed (its runs are in `explore_runs_session33_{a,b}.csv`). For each pair of methods run on the same system,
seed and size, the log ratio of their nRMSE; prints the geometric mean over pairs, its
standard error, the ratio per size and, for the explorer against random ramps, per cell
(system and size: geometric mean over the seeds). Standard library only.
"""
import collections
import csv
import math
import sys

PAIRS = [
    ("random-ramps", "explore-ramps"),
    ("random-ramps", "explore-ramps-alpha0.5"),
    ("explore-ramps", "explore-ramps-alpha0.5"),
    ("random-ramps", "explore-ramps-alpha0"),
    ("explore-ramps-alpha0", "explore-ramps"),
    ("random-ramps", "explore-ramps-error"),
    ("explore-ramps", "explore-ramps-error"),
]


def main(argv):
    if len(argv) < 3:
        sys.exit(__doc__)
    seeds = {int(s) for s in argv[1].split(",")}
    runs = collections.defaultdict(dict)
    for path in argv[2:]:
        for r in csv.DictReader(open(path)):
            if r.get("seed", "").isdigit() and int(r["seed"]) in seeds:
                runs[(r["system"], int(r["seed"]), int(r["samples"]))][r["method"]] = float(r["nrmse"])
    for a, b in PAIRS:
        cells = collections.defaultdict(list)
        for (system, _, n), m in runs.items():
            if a in m and b in m:
                cells[(system, n)].append(math.log(m[b] / m[a]))
        logs = [x for c in cells.values() for x in c]
        if len(logs) < 2:
            continue
        mean = sum(logs) / len(logs)
        sd = math.sqrt(sum((x - mean) ** 2 for x in logs) / (len(logs) - 1))
        per_n = collections.defaultdict(list)
        for (_, n), c in cells.items():
            per_n[n] += c
        worse = sum(1 for c in cells.values() if sum(c) > 0)
        sizes = ", ".join(f"{n} samples {math.exp(sum(c) / len(c)):.3f}" for n, c in sorted(per_n.items()))
        print(f"{b} / {a}: {math.exp(mean):.3f} over {len(logs)} pairs (standard error of the log "
              f"{sd / math.sqrt(len(logs)):.3f}); worse in {worse} of {len(cells)} cells; {sizes}")
        if (a, b) == ("random-ramps", "explore-ramps"):
            for (system, n), c in sorted(cells.items()):
                print(f"    {system:15} {n:5} {math.exp(sum(c) / len(c)):.3f} ({len(c)} seeds)")


if __name__ == "__main__":
    main(sys.argv)
