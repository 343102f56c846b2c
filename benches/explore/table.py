"""Summarises the CSV of the harness program `explore_eval` (`cargo run --release -p hbn-harness
--bin explore_eval -- --systems ... --sizes ... --seeds ...`) as the Markdown tables of
docs/exploration.md: mean nRMSE per system, amount of data and method (over
seeds), each method's ratio to random ramps, the geometric means against random ramps and
against the thesis' random walk, and the smallest amount of explored data that reaches the
accuracy of random ramps on the largest amount. Then the paired comparison: for each method
against random ramps and against the default explorer, the geometric mean over runs of the
same system, seed and size of the nRMSE ratio, with the standard error of its log and the
ratio per size (the cell table's ratios are of means over the seeds).

With `random-ramps-b` in the runs (a second, independent draw of random ramps: an A/A
comparison), it ends with what that says about a bar of "no worse than random ramps in every
cell": the spread of one run's log nRMSE ratio between two
draws, and the true ratio a method would need in every cell to pass the bar in 12 cells with
probability 0.9, for cells of 3 and of 6 seeds (normal approximation of the cell mean's log
ratio). And, for each explorer, its paired ratio to both draws' geometric mean.

Usage: python benches/explore/table.py [--seeds 21,22,...] RUNS.csv [RUNS2.csv ...]
(`--seeds`: only the runs of these seeds.)
"""
from statistics import NormalDist
import csv
import math
import sys
from collections import defaultdict

ORDER = ["random-ramps", "random-walk", "explore-ramps", "explore-steps"]
NAMES = {
    "random-ramps": "random ramps",
    "random-walk": "random walk (thesis)",
    "explore-ramps": "explorer (ramps, default)",
    "explore-steps": "explorer (thesis steps)",
    "explore-ramps-variance": "explorer (variance criterion)",
    "explore-ramps-reduction": "explorer (reduction criterion)",
}


def name(method):
    """The table's name of a method: NAMES, or the method as written for a variant."""
    return NAMES.get(method, method)


def mean(v):
    return sum(v) / len(v)


def geo(v):
    return math.exp(sum(math.log(x) for x in v) / len(v))


def spread(v):
    """Mean of `v` and its sample standard deviation."""
    mu = mean(v)
    return mu, math.sqrt(sum((x - mu) ** 2 for x in v) / (len(v) - 1))


def paired(by_run, methods):
    """Prints each method against random ramps and against the default explorer, paired on
    the runs (system, seed, size) both have."""
    for base in ["random-ramps", "explore-ramps"]:
        for m in methods:
            if m in (base, "random-ramps"):
                continue
            logs = defaultdict(list)  # samples -> log ratios
            for (_, _, n), got in by_run.items():
                if base in got and m in got:
                    logs[n].append(math.log(got[m] / got[base]))
            every = [x for v in logs.values() for x in v]
            if len(every) < 2:
                continue
            mu, sd = spread(every)
            se = sd / math.sqrt(len(every))
            sizes = ", ".join(f"{n} samples {math.exp(mean(v)):.3f}" for n, v in sorted(logs.items()))
            print(f"- {name(m)} / {name(base)}: {math.exp(mu):.3f} over {len(every)} runs "
                  f"(standard error of the log {se:.3f}); {sizes}")


def main(argv):
    seeds = None
    if len(argv) >= 2 and argv[0] == "--seeds":
        seeds = {int(s) for s in argv[1].split(",")}
        argv = argv[2:]
    runs = defaultdict(list)  # (system, samples, method) -> [nrmse]
    by_run = defaultdict(dict)  # (system, seed, samples) -> {method: nrmse}
    for path in argv:
        with open(path) as f:
            for row in csv.DictReader(f):
                try:
                    seed = int(row["seed"])
                    if seeds is not None and seed not in seeds:
                        continue
                    key = (row["system"], int(row["samples"]), row["method"])
                    value = float(row["nrmse"])
                except (KeyError, ValueError):
                    continue
                runs[key].append(value)
                by_run[(key[0], seed, key[1])][key[2]] = value
    systems = sorted({k[0] for k in runs})
    sizes = sorted({k[1] for k in runs})
    # Known methods in their order, then any other (a variant measured beside them), in the
    # order of first appearance, named as written.
    seen = list(dict.fromkeys(k[2] for k in runs))
    methods = [m for m in ORDER if m in seen] + [m for m in seen if m not in ORDER]
    head = ["system", "samples", "seeds"]
    for m in methods:
        head += [name(m)] + (["ratio"] if m != "random-ramps" else [])
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    ratios = defaultdict(list)
    vs_walk = defaultdict(list)
    for s in systems:
        for n in sizes:
            base = runs.get((s, n, "random-ramps"))
            if not base:
                continue
            walk = runs.get((s, n, "random-walk"))
            cells = [s, str(n), str(len(base))]
            for m in methods:
                v = runs.get((s, n, m))
                if m == "random-ramps":
                    cells.append(f"{mean(base):.4f}")
                    continue
                if not v:
                    cells += ["", ""]
                    continue
                cells += [f"{mean(v):.4f}", f"{mean(v) / mean(base):.2f}"]
                ratios[m].append(mean(v) / mean(base))
                if walk and m.startswith("explore"):
                    vs_walk[m].append(mean(v) / mean(walk))
            print("| " + " | ".join(cells) + " |")
    print()
    for m, r in ratios.items():
        print(f"- {name(m)} / random ramps: geometric mean {geo(r):.2f} over {len(r)} cells, "
              f"no worse in {sum(x <= 1.0 for x in r)}")
    for m, r in vs_walk.items():
        print(f"- {name(m)} / random walk: geometric mean {geo(r):.2f} over {len(r)} cells, "
              f"no worse in {sum(x <= 1.0 for x in r)}")
    print("\nData needed to reach the accuracy of random ramps on the most samples:")
    for s in systems:
        top = max(n for n in sizes if runs.get((s, n, "random-ramps")))
        target = mean(runs[(s, top, "random-ramps")])
        for m in methods:
            if not m.startswith("explore"):
                continue
            need = next((n for n in sizes
                         if runs.get((s, n, m)) and mean(runs[(s, n, m)]) <= target), None)
            said = f"{need} samples" if need else f"more than {top}"
            print(f"- {s}, {name(m)}: {said} (random ramps: {top} samples, nRMSE {target:.4f})")
    print("\nPaired on the runs:")
    paired(by_run, methods)
    if "random-ramps-b" in methods:
        same_draw(by_run, methods)


def same_draw(by_run, methods, cells=12, chance=0.9):
    """Random ramps against a second draw of themselves (the A/A comparison), what effect the
    every-cell bar needs, and each explorer against both draws' geometric mean."""
    logs = [math.log(g["random-ramps-b"] / g["random-ramps"]) for g in by_run.values()
            if "random-ramps" in g and "random-ramps-b" in g]
    if len(logs) < 3:
        return
    _, sd = spread(logs)
    # Each of `cells` cells must come out no worse: per cell probability chance^(1/cells).
    z = NormalDist().inv_cdf(chance ** (1.0 / cells))
    print(f"\nTwo draws of random ramps: one run's log nRMSE ratio has standard deviation "
          f"{sd:.3f} (a factor {math.exp(sd):.2f}) over {len(logs)} runs.")
    for k in (3, 6):
        # A cell's log ratio (method over random ramps) has variance sd^2 / k: sd^2 already
        # holds both runs' spread.
        need = math.exp(-z * sd / math.sqrt(k))
        print(f"- to be no worse in all {cells} cells of {k} seeds with probability {chance}, "
              f"a method needs a true ratio of {need:.2f} or less in every cell")
    for m in methods:
        if not m.startswith("explore"):
            continue
        by_size = defaultdict(list)  # samples -> log ratios
        for (_, _, n), g in by_run.items():
            if m in g and "random-ramps" in g and "random-ramps-b" in g:
                by_size[n].append(math.log(g[m])
                                  - 0.5 * (math.log(g["random-ramps"]) + math.log(g["random-ramps-b"])))
        both = [x for v in by_size.values() for x in v]
        if len(both) < 2:
            continue

        def interval(v):
            mb, sd = spread(v)
            se = sd / math.sqrt(len(v))
            return (f"{math.exp(mb):.3f} over {len(v)} runs (standard error of the log {se:.3f}; "
                    f"95% interval {math.exp(mb - 1.96 * se):.3f} to {math.exp(mb + 1.96 * se):.3f})")
        sizes = "; ".join(f"{n} samples {interval(v)}" for n, v in sorted(by_size.items()) if len(v) > 1)
        print(f"- {name(m)} / both draws' geometric mean: {interval(both)}; {sizes}")


if __name__ == "__main__":
    main(sys.argv[1:])
