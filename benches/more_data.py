#!/usr/bin/env python3
"""Whether more data buys accuracy: the default model trained on one long log against the
same model trained on the log's first samples.

For every simulator x noise gain x seed: one simulated log of the largest ``--sizes`` entry
(``hbn.simulate``, the cell's seed); one model per size by ``HysteresisModel.fit`` on the
log's first ``size`` samples (keywords from ``--fit``, default none: hbn's defaults); each
scored by the nRMSE of its default mode on ``--tests`` fresh test logs of ``--test-steps``
samples (seeds 1000 + 10 * seed + i, never trained or validated on) against their true state.

It prints the machine, the date and the command, then a JSON line per cell (nRMSE per size
and test log, training seconds, the candidate training chose), then per gain and overall the
mean over cells of the largest size's nRMSE / the smallest's and the worst cell.

Command::

    pip install ./hbn-py
    python3 benches/more_data.py --systems bouc-wen,duhem,preisach --gains 1,3 --seeds 1,2 \\
        [--sizes 10000,100000] [--fit '{"n_inducing": 128}']
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import platform
import sys
import time

import numpy as np

import hbn


def nrmse(x: np.ndarray, ref: np.ndarray) -> float:
    return float(np.sqrt(np.mean((x - ref) ** 2)) / (ref.max() - ref.min()))


def chosen(params: dict) -> str:
    """The candidate training chose, as ``hbn train`` names it (``exact``, ``m=64 lags=1``)."""
    m = params.get("n_inducing")
    out = "exact" if m is None else f"m={m}"
    if params.get("lags"):
        out += " lags=" + ",".join(f"{t:g}" for t in params["lags"])
    if params.get("sensor_inputs") != "thesis":
        out += f" sensor={params.get('sensor_inputs')}"
    return out


def main(argv: list | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--systems", default="bouc-wen,duhem,preisach")
    p.add_argument("--gains", default="1,3")
    p.add_argument("--seeds", default="1,2")
    p.add_argument("--sizes", default="10000,100000")
    p.add_argument("--tests", type=int, default=3)
    p.add_argument("--test-steps", type=int, default=3000)
    p.add_argument("--fit", default="{}", help="keywords for HysteresisModel.fit, as JSON")
    a = p.parse_args(argv)
    systems = [s for s in a.systems.split(",") if s]
    gains = [float(g) for g in a.gains.split(",") if g]
    seeds = [int(s) for s in a.seeds.split(",") if s]
    sizes = sorted(int(s) for s in a.sizes.split(",") if s)
    kwargs = json.loads(a.fit)
    if len(sizes) < 2:
        p.error("--sizes needs at least two sizes")
    print(f"# {platform.node()} {platform.machine()} {platform.processor()}")
    print(f"# {datetime.datetime.now(datetime.timezone.utc).isoformat(timespec='seconds')}")
    print(f"# {' '.join([sys.argv[0], *(argv if argv is not None else sys.argv[1:])])}")
    ratios: dict = {}
    for system in systems:
        for gain in gains:
            for seed in seeds:
                log = hbn.simulate(system, sizes[-1], seed=seed, noise_gain=gain)
                tests = [
                    hbn.simulate(system, a.test_steps, seed=1000 + 10 * seed + i, noise_gain=gain)
                    for i in range(a.tests)
                ]
                row = {"system": system, "gain": gain, "seed": seed, "sizes": {}}
                for n in sizes:
                    t0 = time.perf_counter()
                    model = hbn.HysteresisModel.fit(
                        log["u"][:n], log["x"][:n], log["y"][:n], seed=seed, **kwargs
                    )
                    secs = time.perf_counter() - t0
                    scores = [
                        nrmse(np.asarray(model.estimate(t["u"], t["y"]).x), t["x"]) for t in tests
                    ]
                    row["sizes"][str(n)] = {
                        "nrmse": float(np.mean(scores)),
                        "tests": scores,
                        "seconds": round(secs, 2),
                        "chosen": chosen(model.params),
                        "mode": model.default_mode,
                    }
                small = row["sizes"][str(sizes[0])]["nrmse"]
                large = row["sizes"][str(sizes[-1])]["nrmse"]
                row["ratio"] = large / small
                ratios.setdefault(gain, []).append(row["ratio"])
                print(json.dumps(row), flush=True)
    everything = [r for rs in ratios.values() for r in rs]
    for gain, rs in sorted(ratios.items()):
        print(f"gain {gain:g}: {sizes[-1]} / {sizes[0]} samples, mean ratio {np.mean(rs):.3f}, "
              f"worst {max(rs):.3f} over {len(rs)} cells")
    print(f"all: mean ratio {np.mean(everything):.3f}, worst {max(everything):.3f} "
          f"(geometric mean {math.exp(np.mean(np.log(everything))):.3f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
