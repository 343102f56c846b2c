"""hbn's default with and without the state-only sensor candidate (runs of
docs/data/sensor_inputs_session35.sh) against the baselines of a runner grid JSON on the same
seeds and protocol (benches/baselines/run.py --grid: the same simulated logs).

    python3 docs/data/sensor_inputs_vs_baselines_session35.py RUNS.jsonl GRID.json[,GRID2.json]

Per (system, gain) cell: the mean test nRMSE over seeds of each, the better baseline's, and
hbn / better baseline for both variants; the runner's own hbn nRMSE beside the `thesis`
variant (the same default before session 35: equal unless the machine's arithmetic moved)."""
import json
import math
import sys
from collections import defaultdict

runs = [json.loads(l) for l in open(sys.argv[1]) if l.strip()]
grid = [r for f in sys.argv[2].split(",") for r in json.load(open(f))["runs"]]
ours = defaultdict(lambda: defaultdict(list))
for r in runs:
    ours[(r["system"], float(r["gain"]))][r["variant"]].append(r["r"]["nrmse"])
base = defaultdict(lambda: defaultdict(list))
for r in grid:
    for m, v in r["report"]["methods"].items():
        if isinstance(v, dict) and "nrmse" in v:
            base[(r["system"], float(r["gain"]))][m].append(v["nrmse"])
mean = lambda v: sum(v) / len(v)
print("| system | gain | sk-gp-ekf | lstm | hbn (runner) | thesis | default | thesis / better | default / better |")
print("|---|---|---|---|---|---|---|---|---|")
ratios = defaultdict(list)
for cell in sorted(ours):
    o, b = ours[cell], base.get(cell)
    if not b or "default" not in o or "thesis" not in o:
        continue
    better = min(mean(b[m]) for m in ("sk-gp-ekf", "lstm") if m in b)
    t, d = mean(o["thesis"]), mean(o["default"])
    ratios["thesis"].append(t / better)
    ratios["default"].append(d / better)
    print(
        f"| {cell[0]} | {cell[1]:g} | {mean(b['sk-gp-ekf']):.4f} | {mean(b['lstm']) if 'lstm' in b else float('nan'):.4f} "
        f"| {mean(b['hbn']):.4f} | {t:.4f} | {d:.4f} | {t / better:.2f}x | {d / better:.2f}x |"
    )
for k, v in ratios.items():
    gm = math.exp(sum(map(math.log, v)) / len(v))
    print(f"{k}: geometric mean over {len(v)} cells {gm:.3f}x the better baseline; at most 0.8x in {sum(x <= 0.8 for x in v)}, above 1 in {sum(x > 1 for x in v)}")
