"""Compares hbn in two grid runs of ``run.py --grid`` on the same cells (e.g. the default
against model selection, ``--hbn-params``): per (system, gain) the mean nRMSE of hbn's default
mode in each, the better baseline of the second run (of the first, if the second ran hbn
alone), the ratios, and the calibration of each.

    python3 benches/baselines/compare_grids.py A/grid.json B/grid.json [--names default,selection]
"""

import argparse
import json
import math
from pathlib import Path
from typing import Any, Dict, List, Mapping, Sequence, Tuple

BASELINES = ("sk-gp-ekf", "lstm")


def cells(doc: Mapping[str, Any]) -> Dict[Tuple[str, float], List[Mapping[str, Any]]]:
    out: Dict[Tuple[str, float], List[Mapping[str, Any]]] = {}
    for r in doc["runs"]:
        out.setdefault((r["system"], float(r["gain"])), []).append(r)
    return out


def mean(v: Sequence[float]) -> float:
    return sum(v) / len(v) if v else math.nan


def metric(runs: Sequence[Mapping[str, Any]], method: str, key: str) -> float:
    vals = [r["report"]["methods"][method][key] for r in runs if method in r["report"]["methods"]]
    return mean([v for v in vals if v is not None])


def table(a: Mapping[str, Any], b: Mapping[str, Any], names: Sequence[str]) -> str:
    ca, cb = cells(a), cells(b)
    na, nb = names
    lines = [
        f"| system | gain | hbn {na} | hbn {nb} | {nb} / {na} | better baseline | {na} / baseline "
        f"| {nb} / baseline | 2-sigma {na} / {nb} | NEES {na} / {nb} | chosen ({nb}) |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    logs = {"ab": [], "a": [], "b": []}
    for key in sorted(set(ca) & set(cb)):
        ra, rb = ca[key], cb[key]
        ea, eb = metric(ra, "hbn", "nrmse"), metric(rb, "hbn", "nrmse")
        # The baselines of the second run, or of the first where the second ran hbn alone.
        have = [m for m in BASELINES if any(m in r["report"]["methods"] for r in rb)]
        rbase = rb if have else ra
        have = have or [m for m in BASELINES if any(m in r["report"]["methods"] for r in ra)]
        base = min(metric(rbase, m, "nrmse") for m in have) if have else math.nan
        chosen: Dict[str, int] = {}
        for r in rb:
            c = r["report"]["methods"]["hbn"].get("config")
            if c:
                chosen[c] = chosen.get(c, 0) + 1
        logs["ab"].append(math.log(eb / ea))
        logs["a"].append(math.log(ea / base))
        logs["b"].append(math.log(eb / base))
        lines.append(
            f"| {key[0]} | {key[1]:g} | {ea:.4f} | {eb:.4f} | {eb / ea:.2f} | {base:.4f} | {ea / base:.2f} "
            f"| {eb / base:.2f} | {metric(ra, 'hbn', 'coverage_2sigma'):.3f} / {metric(rb, 'hbn', 'coverage_2sigma'):.3f} "
            f"| {metric(ra, 'hbn', 'mean_nees'):.2f} / {metric(rb, 'hbn', 'mean_nees'):.2f} "
            f"| {', '.join(f'{k} x{v}' for k, v in sorted(chosen.items())) or '-'} |"
        )
    g = {k: math.exp(mean(v)) for k, v in logs.items()}
    lines.append("")
    lines.append(
        f"Geometric means over {len(logs['ab'])} cells: {nb} / {na} {g['ab']:.3f}; "
        f"{na} / better baseline {g['a']:.3f}; {nb} / better baseline {g['b']:.3f}. "
        f"{nb} better than {na} in {sum(v < 0 for v in logs['ab'])} cells."
    )
    return "\n".join(lines) + "\n"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("a", type=Path)
    ap.add_argument("b", type=Path)
    ap.add_argument("--names", default="default,selection")
    args = ap.parse_args()
    names = args.names.split(",")
    if len(names) != 2:
        ap.error("--names takes two names")
    print(table(json.loads(args.a.read_text()), json.loads(args.b.read_text()), names), end="")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
