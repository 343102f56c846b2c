"""Cost of the explorer with Python in the robot's loop (docs/exploration.md).

Drives ``hbn.Simulator("bouc-wen")`` (noise gain 1, seed 1) with ``hbn.Explorer`` (bounds
[0, 1], ``max_step`` 0.02, seed 1, default settings) for N samples, timing every ``propose()``
and ``observe()`` call with ``time.perf_counter``, then ``model()``. Prints one line of means,
the seeking phase's mean ``propose()``, and the worst sample.

    python benches/explore/loop_time.py [N] [--lag L] [--rate HZ] [--criterion C]
    # defaults: 1000 samples, lag 0, unpaced, the library's criterion

``--lag L`` runs the refits beside the loop (``hbn.Explorer(lag=L)``); ``--rate HZ`` paces
the loop as a robot would (each sample starts 1/HZ s after the last) and counts the samples
whose ``propose()`` + ``observe()`` overran the period.
"""

import argparse
import time

import numpy as np

import hbn


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("n", nargs="?", type=int, default=1000)
    ap.add_argument("--lag", type=int, default=0)
    ap.add_argument("--rate", type=float, default=None)
    ap.add_argument("--criterion", default=None, help="variance or reduction")
    args = ap.parse_args()
    n = args.n
    explorer = hbn.Explorer(
        0.0, 1.0, 0.02, rate_hz=100.0, seed=1, lag=args.lag, criterion=args.criterion
    )
    robot = hbn.Simulator("bouc-wen", seed=1, noise_gain=1.0)
    random_samples = hbn.default_explore_params()["random_samples"]
    period = 1.0 / args.rate if args.rate else 0.0
    t_propose, t_observe = [], []
    start = time.perf_counter()
    tick = start
    for _ in range(n):
        if period:
            tick += period
            pause = tick - time.perf_counter()
            if pause > 0:
                time.sleep(pause)
        a = time.perf_counter()
        u = explorer.propose()
        b = time.perf_counter()
        x, y = robot.step(u)
        c = time.perf_counter()
        explorer.observe(u, x, y)
        d = time.perf_counter()
        t_propose.append(b - a)
        t_observe.append(d - c)
    total = time.perf_counter() - start
    tp, to = np.array(t_propose), np.array(t_observe)
    seeking = tp[random_samples:] if n > random_samples else tp
    paced = ""
    if period:
        over = int(np.sum(tp + to > period))
        paced = f", paced at {args.rate:g} Hz: {over} samples overran the period"
    print(
        f"{n} samples, lag {args.lag}: mean per sample {1e3 * total / n:.2f} ms, "
        f"propose {1e3 * tp.mean():.3f} ms "
        f"(seeking phase {1e3 * seeking.mean():.3f} ms, max {1e3 * tp.max():.1f} ms), "
        f"observe {1e3 * to.mean():.2f} ms, worst sample {(tp + to).max():.3f} s{paced}"
    )
    a = time.perf_counter()
    explorer.model()
    print(f"model() {time.perf_counter() - a:.1f} s")


if __name__ == "__main__":
    main()
