#!/usr/bin/env python3
"""Train an HBN on a simulated soft actuator, estimate its state, and plot the result.

    pip install "./hbn-py[plot]"                          (the wheel and matplotlib)
    python examples/train_and_plot.py --out hbn_example.png

Simulates the rate-dependent ``soft-actuator`` system (pneumatic lag, Bouc-Wen bend, creep,
viscoelastic strain sensor), fits the Hysteresis Bayesian Network, estimates the bend ``x`` from
the valve input ``u`` and the sensor ``y`` with the EKF and the EKF+BLR, and plots the estimates
+-2 std against the truth, with the hysteresis loops ``u -> x`` and ``x -> y``. Prints the
nRMSE of each estimate and of the open-loop GP simulation.
"""

import argparse
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


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="hbn_example.png", help="the PNG to write")
    ap.add_argument("--system", default="soft-actuator", choices=hbn.SYSTEMS)
    ap.add_argument("--train-samples", type=int, default=1200)
    ap.add_argument("--test-samples", type=int, default=600)
    ap.add_argument("--noise-gain", type=float, default=1.0)
    ap.add_argument("--seed", type=int, default=1, help="seed of the training run (the test run uses seed + 1)")
    args = ap.parse_args(argv)

    train = hbn.simulate(args.system, args.train_samples, seed=args.seed, noise_gain=args.noise_gain)
    test = hbn.simulate(args.system, args.test_samples, seed=args.seed + 1, noise_gain=args.noise_gain)
    # Fewer support points and one optimiser start per GP keep the example quick.
    model = hbn.HysteresisModel.fit(train["u"], train["x"], train["y"], max_points=300, n_starts=1)
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

    t = np.arange(len(test["u"])) / model.rate_hz
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
    fig.suptitle(f"hbn on the simulated '{args.system}' system")
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    print("wrote", args.out)
    return scores


if __name__ == "__main__":
    main()
