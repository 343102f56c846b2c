"""Prints the Markdown tables of docs/results.md, "Filter-aware training", from the JSON files
written by the `tuning` example:

    cargo run --release -p hbn-pipeline --example tuning -- docs/data/tuning_repeat.json \
        maxwell-slip,generalized-pi,bouc-wen,duhem,preisach,soft-actuator 1 1,2 repeat
    cargo run --release -p hbn-pipeline --example tuning -- docs/data/tuning_varied.json \
        maxwell-slip,generalized-pi,bouc-wen,duhem,preisach,soft-actuator 1 1,2 varied
    python3 docs/data/tuning_table.py
"""
import json
import math
import os

HERE = os.path.dirname(os.path.abspath(__file__))


def cell(r):
    d = r["default"]
    c = d["calibration"]
    return d["nrmse"], c["coverage_2sigma"], c["mean_nees"], c["nlpd"]


def table(path, title):
    rows = json.load(open(path))
    keyed = {}
    for r in rows:
        keyed.setdefault((r["system"], r["seed"]), {})[r["validation"] > 0] = r
    print(f"\n{title}\n")
    print("| system | seed | nRMSE untuned / tuned | 2-sigma coverage | mean NEES | NLPD | default mode | training s |")
    print("|---|---|---|---|---|---|---|---|")
    agg = {False: [], True: []}
    for (system, seed), pair in sorted(keyed.items()):
        if False not in pair or True not in pair:
            continue
        a, b = cell(pair[False]), cell(pair[True])
        agg[False].append(a)
        agg[True].append(b)
        print(
            f"| {system} | {seed} | {a[0]:.4f} / {b[0]:.4f} | {100*a[1]:.1f}% / {100*b[1]:.1f}% "
            f"| {a[2]:.2f} / {b[2]:.2f} | {a[3]:.2f} / {b[3]:.2f} | {pair[True]['default_mode']} "
            f"| {pair[False]['seconds']:.1f} / {pair[True]['seconds']:.1f} |"
        )
    n = len(agg[True])
    if n:
        def gmean(v):
            return math.exp(sum(math.log(x) for x in v) / len(v))

        def mean(v):
            return sum(v) / len(v)

        ratio = gmean([b[0] / a[0] for a, b in zip(agg[False], agg[True])])
        better = sum(b[0] < a[0] for a, b in zip(agg[False], agg[True]))
        print(
            f"| **all {n}** | | tuned/untuned nRMSE x{ratio:.2f} (geo. mean; better in {better}/{n}) "
            f"| {100*mean([a[1] for a in agg[False]]):.1f}% / {100*mean([b[1] for b in agg[True]]):.1f}% "
            f"| {mean([a[2] for a in agg[False]]):.2f} / {mean([b[2] for b in agg[True]]):.2f} "
            f"| {mean([a[3] for a in agg[False]]):.2f} / {mean([b[3] for b in agg[True]]):.2f} | | |"
        )


if __name__ == "__main__":
    table(os.path.join(HERE, "tuning_repeat.json"), "Thesis protocol (one training input repeated 10 times)")
    table(os.path.join(HERE, "tuning_varied.json"), "Varied inputs (10 training runs, each its own input)")
