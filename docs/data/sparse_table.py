"""Prints the "Sparse or exact" table of docs/results.md from docs/data/sparse_vs_exact.json
(written by `cargo run --release -p hbn-pipeline --example sparse_vs_exact`). Standard library only.

    python3 docs/data/sparse_table.py [docs/data/sparse_vs_exact.json]
"""
import json
import sys
from collections import defaultdict

path = sys.argv[1] if len(sys.argv) > 1 else "docs/data/sparse_vs_exact.json"
rows = json.load(open(path))
kinds = [k[: -len("_ekf")] for k in rows[0] if k.endswith("_ekf")]
cells = defaultdict(list)
for r in rows:
    cells[(r["system"], r["gain"])].append(r)
head = "| system | gain | " + " | ".join(f"{k} EKF / EKF+BLR" for k in kinds) + " | sparse/exact (EKF) |"
print(head)
print("|" + "---|" * (head.count("|") - 1))
worse = 0
for (system, gain), rs in cells.items():
    mean = lambda key: sum(r[key] for r in rs) / len(rs)  # noqa: E731
    vals = " | ".join(f"{mean(k + '_ekf'):.4f} / {mean(k + '_ekf_blr'):.4f}" for k in kinds)
    ratio = mean(kinds[-1] + "_ekf") / mean(kinds[0] + "_ekf")
    worse += ratio > 1.0
    print(f"| {system} | {gain:g} | {vals} | {ratio:.2f} |")
print(f"\n{len(cells)} cells (mean of {len(rs)} seeds each); sparse worse than exact in {worse}.")
secs = {k: sum(r[k + "_seconds"] for r in rows) / len(rows) for k in kinds}
print("Mean training seconds per case (both GPs): " + ", ".join(f"{k} {v:.1f}" for k, v in secs.items()))
