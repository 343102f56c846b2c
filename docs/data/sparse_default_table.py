"""Compares two model kinds of `sparse_vs_exact` runs in their **default** (validated) mode:
nRMSE per cell (mean of the seeds), the ratio B/A, and each one's 2-sigma coverage and mean
NEES. Reads the JSON arrays the example writes or the JSON lines it prints on stderr (any
mix, several files). Standard library only.

    python3 docs/data/sparse_default_table.py A_KIND B_KIND FILE...
    python3 docs/data/sparse_default_table.py exact500 sparse64 runs.json more.jsonl
"""
import json
import math
import sys
from collections import defaultdict


def read_rows(path):
    text = open(path).read().strip()
    if text.startswith("["):
        return json.loads(text)
    return [json.loads(line) for line in text.splitlines() if line.startswith("{")]


def main(argv):
    if len(argv) < 4:
        sys.exit(__doc__)
    a, b, paths = argv[1], argv[2], argv[3:]
    rows = {}
    for p in paths:
        for r in read_rows(p):
            if f"{a}_default" in r and f"{b}_default" in r:
                rows[(r["system"], r["gain"], r["seed"])] = r
    cells = defaultdict(list)
    for (system, gain, _), r in sorted(rows.items()):
        cells[(system, gain)].append(r)
    print(f"| system | gain | seeds | {a} nRMSE | {b} nRMSE | {b}/{a} | 2-sigma coverage {a} / {b} | mean NEES {a} / {b} |")
    print("|---|---|---|---|---|---|---|---|")
    worse, logs, cov_ok, nees_ok = 0, [], [0, 0], [0, 0]
    for (system, gain), rs in cells.items():
        def mean(f):
            return sum(f(r) for r in rs) / len(rs)

        na, nb = mean(lambda r: r[f"{a}_default"]), mean(lambda r: r[f"{b}_default"])
        ca = mean(lambda r: r[f"{a}_calibration"]["coverage_2sigma"])
        cb = mean(lambda r: r[f"{b}_calibration"]["coverage_2sigma"])
        ea = mean(lambda r: r[f"{a}_calibration"]["mean_nees"])
        eb = mean(lambda r: r[f"{b}_calibration"]["mean_nees"])
        worse += nb > na
        for i, (c, e) in enumerate([(ca, ea), (cb, eb)]):
            cov_ok[i] += 0.90 <= c <= 0.98
            nees_ok[i] += 0.5 <= e <= 2.0
        logs += [math.log(r[f"{b}_default"] / r[f"{a}_default"]) for r in rs]
        print(f"| {system} | {gain:g} | {len(rs)} | {na:.4f} | {nb:.4f} | {nb / na:.2f} | {ca:.3f} / {cb:.3f} | {ea:.2f} / {eb:.2f} |")
    n = len(cells)
    print(f"\n{len(rows)} runs, {n} cells. {b}/{a}: geometric mean of per-run ratios "
          f"{math.exp(sum(logs) / len(logs)):.3f}; {b} worse in {worse} of {n} cells.")
    print(f"2-sigma coverage in [0.90, 0.98]: {a} {cov_ok[0]}/{n}, {b} {cov_ok[1]}/{n}; "
          f"mean NEES in [0.5, 2]: {a} {nees_ok[0]}/{n}, {b} {nees_ok[1]}/{n}.")
    for k in (a, b):
        secs = [r[f"{k}_seconds"] for r in rows.values()]
        print(f"{k}: mean training seconds per case {sum(secs) / len(secs):.1f}")


if __name__ == "__main__":
    main(sys.argv)
