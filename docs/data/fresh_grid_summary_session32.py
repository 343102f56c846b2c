"""Summary of grid runs of benches/baselines/run.py against the goals of issue 10, on cell
means (the mean of a cell's seeds, as docs/results.md counts them): hbn's nRMSE over the
better baseline's, cells at most 0.8x, 2-sigma coverage in [0.90, 0.98], mean NEES in
[0.5, 2]; per-run ratios too, since one diverged baseline run can make a cell mean.
Standard library only.

    python3 docs/data/fresh_grid_summary_session32.py GRID.json [GRID.json ...]
"""
import json
import math
import sys
from collections import defaultdict


def main(paths):
    cells = defaultdict(list)
    for p in paths:
        for r in json.load(open(p))["runs"]:
            cells[(r["system"], r["gain"])].append(r["report"]["methods"])
    groups = defaultdict(list)
    for (system, gain), runs in sorted(cells.items()):
        mean = lambda m, k="nrmse": sum(x[m][k] for x in runs) / len(runs)
        h, sk, ls = mean("hbn"), mean("sk-gp-ekf"), mean("lstm")
        cov, nees = mean("hbn", "coverage_2sigma"), mean("hbn", "mean_nees")
        per_run = [x["hbn"]["nrmse"] / min(x["sk-gp-ekf"]["nrmse"], x["lstm"]["nrmse"]) for x in runs]
        ratio = h / min(sk, ls)
        groups[system].append((gain, ratio, cov, nees, per_run))
        print(f"{system:15s} {gain:4.0f}  hbn {h:.4f}  sk {sk:.4f}  lstm {ls:.4f}  "
              f"hbn/better {ratio:.2f}  per run {' '.join(f'{v:.2f}' for v in per_run)}  "
              f"cov2 {cov:.3f}  nees {nees:.2f}")
    allc = [c for g in groups.values() for c in g]
    gm = math.exp(sum(math.log(c[1]) for c in allc) / len(allc))
    runs = [v for c in allc for v in c[4]]
    gmr = math.exp(sum(math.log(v) for v in runs) / len(runs))
    print(f"cells {len(allc)}: hbn / better baseline geometric mean {gm:.3f} (per run {gmr:.3f}); "
          f"at most 0.8x in {sum(c[1] <= 0.8 for c in allc)}; at most 1.0x in {sum(c[1] <= 1.0 for c in allc)}; "
          f"2-sigma coverage in band {sum(0.90 <= c[2] <= 0.98 for c in allc)}; "
          f"mean NEES in band {sum(0.5 <= c[3] <= 2 for c in allc)}")
    for gain in sorted({c[0] for c in allc}):
        sel = [c for c in allc if c[0] == gain]
        g = math.exp(sum(math.log(c[1]) for c in sel) / len(sel))
        print(f"  gain {gain:g}: {g:.3f} over {len(sel)} cells")


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    main(sys.argv[1:])
