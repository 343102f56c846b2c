"""hbn and the baselines against the floor under causal estimation, per judged-grid cell.

usage: python3 docs/data/oracle_floor_compare.py FLOOR.jsonl GRID.json[,GRID2.json] [BASELINES.json[,...]]

FLOOR.jsonl: the lines of `cargo run --release -p hbn-pipeline --example oracle_floor -- SYSTEMS GAINS
SEEDS` (the exact posterior mean of x_k given u, y up to k, the true past states and the true
simulator: no causal estimator has a lower expected squared error). GRID: a run of
`benches/baselines/run.py --grid` with the methods hbn, sk-gp-ekf and lstm on the same seeds;
BASELINES, when given, another run whose sk-gp-ekf and lstm are used instead (several files,
comma-separated, are merged).

Per cell (system, gain; means over the seeds both files have): the floor's nRMSE, hbn's, the
better baseline's, and the ratios to the floor. `0.8 x better / floor` below 1 means that issue
10's bar for the cell (hbn at most 0.8x the better baseline) asks for an error below the floor:
no causal estimator can meet it there, in expectation. The last column, `(hbn - floor) /
(better - floor)`, compares what each is above the floor: a bar that every cell can meet."""
import collections, json, math, sys

floor = {}
for line in open(sys.argv[1]):
    r = json.loads(line)
    floor[(r["system"], float(r["gain"]), int(r["seed"]))] = r["nrmse_oracle"]
def load(paths):
    out = {}
    for path in paths.split(","):
        for r in json.load(open(path))["runs"]:
            out[(r["system"], float(r["gain"]), int(r["seed"]))] = r["report"]["methods"]
    return out


runs = load(sys.argv[2])
if len(sys.argv) > 3:
    base = load(sys.argv[3])
    runs = {k: {**base[k], "hbn": m["hbn"]} for k, m in runs.items() if k in base}
cells = collections.defaultdict(list)
for k in sorted(set(floor) & set(runs)):
    cells[k[:2]].append(k)
print("| system | gain | seeds | floor nRMSE | hbn nRMSE | better baseline nRMSE | hbn / floor | better baseline / floor | 0.8 x better baseline / floor | (hbn - floor) / (better - floor) |")
print("|---|---|---|---|---|---|---|---|---|---|")
infeasible, by_gain, excesses = [], collections.defaultdict(list), []
for (system, gain), ks in sorted(cells.items(), key=lambda c: (c[0][1], c[0][0])):
    mean = lambda f: sum(f(k) for k in ks) / len(ks)
    fl = mean(lambda k: floor[k])
    hbn = mean(lambda k: runs[k]["hbn"]["nrmse"])
    best = min(mean(lambda k, m=m: runs[k][m]["nrmse"]) for m in ("sk-gp-ekf", "lstm") if all(m in runs[k] for k in ks))
    bar = 0.8 * best / fl
    if bar < 1:
        infeasible.append(f"{system} gain {gain:g}")
    by_gain[gain].append((math.log(hbn / fl), math.log(best / fl)))
    excess = (hbn - fl) / (best - fl)
    excesses.append(excess)
    shown = f"**{bar:.2f}**" if bar < 1 else f"{bar:.2f}"
    print(f"| {system} | {gain:g} | {len(ks)} | {fl:.4f} | {hbn:.4f} | {best:.4f} | {hbn / fl:.2f} | {best / fl:.2f} | {shown} | {excess:.2f} |")
print()
for gain, v in sorted(by_gain.items()):
    g = lambda i: math.exp(sum(x[i] for x in v) / len(v))
    print(f"gain {gain:g}: hbn {g(0):.2f}x the floor, the better baseline {g(1):.2f}x (geometric means over {len(v)} cells)")
print(f"hbn's excess over the floor at most 0.8x the better baseline's in {sum(e <= 0.8 for e in excesses)} of {len(excesses)} cells")
print(f"cells where the bar lies below the floor: {len(infeasible)} of {len(cells)}: {', '.join(infeasible) or 'none'}")
