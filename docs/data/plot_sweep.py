"""Plots docs/data/noise_sweep.json (written by the `sweep` example) to docs/img/noise_sweep.png
and prints the Markdown table of docs/results.md.

    cargo run --release -p hbn-pipeline --example sweep -- docs/data/noise_sweep.json
    python3 docs/data/plot_sweep.py
"""
import json
import pathlib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

here = pathlib.Path(__file__).resolve().parent
rows = json.loads((here / "noise_sweep.json").read_text())
systems = sorted({r["system"] for r in rows})
fig, axes = plt.subplots(1, len(systems), figsize=(6 * len(systems), 4.2), squeeze=False)
print("| system | noise gain | nRMSE EKF | nRMSE EKF+BLR | nRMSE open loop | BLR <= EKF (runs) | corr(q, x) EKF | corr(q, x) EKF+BLR |")
print("|---|---|---|---|---|---|---|---|")
for ax, system in zip(axes[0], systems):
    sel = [r for r in rows if r["system"] == system]
    gains = sorted({r["noise_gain"] for r in sel})
    for key, label, style in [("nrmse_ekf", "EKF", "o-"), ("nrmse_ekf_blr", "EKF+BLR", "s-"), ("nrmse_open_loop", "open-loop GP", "^--")]:
        mean = [np.mean([r[key] for r in sel if r["noise_gain"] == g]) for g in gains]
        sd = [np.std([r[key] for r in sel if r["noise_gain"] == g]) for g in gains]
        ax.errorbar(gains, mean, yerr=sd, fmt=style, capsize=3, label=label)
    for g in gains:
        gs = [r for r in sel if r["noise_gain"] == g]
        m = lambda k: np.mean([r[k] for r in gs])  # noqa: E731
        wins = sum(r["nrmse_ekf_blr"] <= r["nrmse_ekf"] for r in gs)
        print(
            f"| {system} | {g:g} | {m('nrmse_ekf'):.4f} +- {np.std([r['nrmse_ekf'] for r in gs]):.4f} | "
            f"{m('nrmse_ekf_blr'):.4f} +- {np.std([r['nrmse_ekf_blr'] for r in gs]):.4f} | {m('nrmse_open_loop'):.4f} | "
            f"{wins}/{len(gs)} | {m('noise_state_corr_ekf'):.2f} | {m('noise_state_corr_ekf_blr'):.2f} |"
        )
    ax.set_xscale("symlog", linthresh=0.5)
    ax.set_yscale("log")
    ax.set_xlabel("noise gain")
    ax.set_ylabel("nRMSE of x (mean +- sd over seeds)")
    ax.set_title(system)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
fig.tight_layout()
out = here.parent / "img" / "noise_sweep.png"
fig.savefig(out, dpi=110)
print(f"\nwrote {out}")
