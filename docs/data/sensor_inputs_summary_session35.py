"""Summary of docs/data/sensor_inputs_session35.sh runs: the default (sensor inputs
`thesis,state`) against `--sensor-inputs thesis`, paired by (system, gain, seed).

    python3 docs/data/sensor_inputs_summary_session35.py RUNS.jsonl [MORE.jsonl ...]

Per gain and per system: the geometric mean of the test-nRMSE ratio default / thesis, runs
better and worse by more than 2%, how often the state-only sensor was chosen; 2-sigma coverage
in [0.9, 0.99] and mean NEES in [0.5, 2] (the grid's bands) for both; training seconds."""
import json
import math
import sys
from collections import defaultdict

rows = [json.loads(l) for f in sys.argv[1:] for l in open(f) if l.strip()]
pairs = defaultdict(dict)
for r in rows:
    pairs[(r["system"], r["gain"], r["seed"])][r["variant"]] = r
pairs = {k: v for k, v in pairs.items() if {"default", "thesis"} <= v.keys()}


def line(label, keys):
    ratios = [pairs[k]["default"]["r"]["nrmse"] / pairs[k]["thesis"]["r"]["nrmse"] for k in keys]
    gm = math.exp(sum(map(math.log, ratios)) / len(ratios))
    better = sum(r < 0.98 for r in ratios)
    worse = sum(r > 1.02 for r in ratios)
    chosen = sum(pairs[k]["default"]["r"]["sensor"] == "state" for k in keys)
    band = lambda v: sum(0.9 <= pairs[k][v]["r"]["cov2"] <= 0.99 for k in keys)
    nees = lambda v: sum(0.5 <= pairs[k][v]["r"]["nees"] <= 2.0 for k in keys)
    secs = sum(pairs[k]["default"]["seconds"] for k in keys) / sum(
        pairs[k]["thesis"]["seconds"] for k in keys
    )
    print(
        f"| {label} | {len(keys)} | {gm:.3f}x | {better} / {worse} | {min(ratios):.2f}-{max(ratios):.2f} "
        f"| {chosen} | {band('default')} / {band('thesis')} | {nees('default')} / {nees('thesis')} | {secs:.2f}x |"
    )


print("| cell | runs | nRMSE default / thesis (geo. mean) | better / worse (2%) | range | state chosen "
      "| coverage in band (default / thesis) | NEES in band | training time |")
print("|---|---|---|---|---|---|---|---|---|")
keys = sorted(pairs)
for g in sorted({k[1] for k in keys}):
    line(f"gain {g}", [k for k in keys if k[1] == g])
for s in sorted({k[0] for k in keys}):
    line(s, [k for k in keys if k[0] == s])
line("all", keys)
