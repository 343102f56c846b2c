#!/usr/bin/env python3
"""Train an HBN on a simulated soft actuator, estimate its state, and plot the result.

    pip install "./hbn-py[plot]"                     (the wheel and matplotlib)
    python examples/train_and_plot.py [out.png]      (default: hbn_example.png)

Simulates the rate-dependent ``soft-actuator`` system (pneumatic lag, Bouc-Wen bend, creep,
viscoelastic strain sensor), fits the Hysteresis Bayesian Network, estimates the bend ``x`` from
the valve input ``u`` and the sensor ``y`` with the EKF and the EKF+BLR, and plots the estimates
+-2 std against the truth, plus the hysteresis loops ``u -> x`` and ``x -> y``.
"""

import sys

try:
    import matplotlib
except ImportError:
    sys.exit('this example plots with matplotlib: pip install "./hbn-py[plot]" (or pip install matplotlib)')

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import hbn  # noqa: E402


def nrmse(est, ref):
    return float(np.sqrt(np.mean((est - ref) ** 2)) / (ref.max() - ref.min()))


def main(out="hbn_example.png"):
    system = "soft-actuator"
    train = hbn.simulate(system, 1200, seed=1, noise_gain=1.0)
    test = hbn.simulate(system, 600, seed=2, noise_gain=1.0)
    model = hbn.HysteresisModel.fit(train["u"], train["x"], train["y"], max_points=300, n_restarts=1)
    ekf = model.estimate(test["u"], test["y"], mode="ekf")
    blr = model.estimate(test["u"], test["y"], mode="ekf-blr")
    open_loop = model.simulate_open_loop(test["u"])
    scores = {
        "ekf": nrmse(ekf.x, test["x"]),
        "ekf-blr": nrmse(blr.x, test["x"]),
        "open-loop": nrmse(open_loop, test["x"]),
    }
    for name, v in scores.items():
        print(f"nRMSE {name:9s}: {v:.4f}")

    t = np.arange(len(test["u"])) / model.rate
    fig, axes = plt.subplots(2, 2, figsize=(12, 7), gridspec_kw={"width_ratios": [2.2, 1]})
    for ax, est, name in ((axes[0, 0], ekf, "ekf"), (axes[1, 0], blr, "ekf-blr")):
        inside = np.mean(np.abs(test["x"] - est.x) <= 2 * est.x_std)
        ax.plot(t, test["x"], "k", lw=1.2, label="true x")
        ax.plot(t, est.x, "C0", lw=1.0, label=f"{name} (nRMSE {scores[name]:.3f})")
        ax.fill_between(t, est.x - 2 * est.x_std, est.x + 2 * est.x_std, color="C0", alpha=0.25,
                        label=f"+-2 std (holds the truth {100 * inside:.0f}% of the time)")
        ax.plot(t, open_loop, "C3--", lw=0.8, label="open-loop GP")
        ax.set_ylabel("x")
        ax.legend(loc="upper right", fontsize=8)
    axes[1, 0].set_xlabel("time [s]")
    axes[0, 1].plot(test["u"], test["x"], "k", lw=0.8, label="true")
    axes[0, 1].plot(test["u"], ekf.x, "C0", lw=0.8, alpha=0.8, label="ekf")
    axes[0, 1].set_xlabel("u (input)")
    axes[0, 1].set_ylabel("x (state)")
    axes[0, 1].set_title("actuator hysteresis u -> x")
    axes[0, 1].legend(fontsize=8)
    axes[1, 1].plot(test["x"], test["y"], "k", lw=0.8)
    axes[1, 1].set_xlabel("x (state)")
    axes[1, 1].set_ylabel("y (sensor)")
    axes[1, 1].set_title("sensor hysteresis x -> y")
    fig.suptitle(f"hbn on the simulated '{system}' system")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print("wrote", out)
    return scores


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "hbn_example.png")
