"""Cost of the explorer with Python in the robot's loop (docs/benchmarks.md, "The explorer").

Drives ``hbn.Simulator("bouc-wen")`` (noise gain 1, seed 1) with ``hbn.Explorer`` (bounds
[0, 1], ``max_step`` 0.02, seed 1, default settings) for N samples, timing every ``propose()``
and ``observe()`` call with ``time.perf_counter``, then ``model()``. Prints one line of means,
the seeking phase's mean ``propose()``, and the worst sample.

    python benches/explore/loop_time.py [N]      # default 1000
"""

import sys
import time

import numpy as np

import hbn


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 1000
    explorer = hbn.Explorer(0.0, 1.0, 0.02, rate=100.0, seed=1)
    robot = hbn.Simulator("bouc-wen", seed=1, noise_gain=1.0)
    random_samples = hbn.default_explore_params()["random_samples"]
    t_propose, t_observe = [], []
    start = time.perf_counter()
    for _ in range(n):
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
    print(
        f"{n} samples: mean per sample {1e3 * total / n:.2f} ms, propose {1e3 * tp.mean():.3f} ms "
        f"(seeking phase {1e3 * seeking.mean():.3f} ms, max {1e3 * tp.max():.1f} ms), "
        f"observe {1e3 * to.mean():.2f} ms, worst sample {(tp + to).max():.2f} s"
    )
    a = time.perf_counter()
    explorer.model()
    print(f"model() {time.perf_counter() - a:.1f} s")


if __name__ == "__main__":
    main()
