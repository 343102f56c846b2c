"""Per-run comparison of hbn's nRMSE between two grid runs of `benches/baselines/run.py`
(session 25: the model-selection check of candidates that lose their own training runs).

usage: python3 docs/data/lost_rule_session25_compare.py OLD.json NEW.json

Prints every run whose nRMSE differs or where a candidate lost the state on its training
runs (the `lost` column of the candidate table; absent in grids from before session 25), and
the geometric mean of NEW / OLD over the runs both have."""
import json
import math
import sys


def load(path):
    return {
        (r["system"], r["gain"], r["seed"]): r["report"]["methods"]["hbn"]
        for r in json.load(open(path))["runs"]
    }


old, new = load(sys.argv[1]), load(sys.argv[2])
logs = []
for key in sorted(set(old) & set(new)):
    o, n = old[key], new[key]
    logs.append(math.log(n["nrmse"] / o["nrmse"]))
    lost = [
        (c["config"].split(" ", 1)[1], c["lost"])
        for c in n["held_out"]["candidates"]
        if c.get("lost")
    ]
    if o["nrmse"] != n["nrmse"] or lost:
        print(
            key,
            f"old {o['nrmse']:.4f} ({o['config'].split(' ', 1)[1]})",
            f"new {n['nrmse']:.4f} ({n['config'].split(' ', 1)[1]})",
            f"2-sd coverage {o['coverage_2sigma']:.3f} -> {n['coverage_2sigma']:.3f}",
            f"lost {lost}",
        )
print(f"NEW / OLD nRMSE: geometric mean {math.exp(sum(logs) / len(logs)):.3f} over {len(logs)} runs")
