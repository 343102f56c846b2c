#!/usr/bin/env python3
"""What logs without the state add to training: a model trained on one log with the state,
against the same log plus logs that recorded only the input and the sensor (their state NaN
throughout, latent in training's expectation-maximisation), and against all logs with the
state (what measuring it everywhere would give).

For every simulator x noise gain x seed: ``1 + --extra`` simulated logs of ``--steps`` samples
(``hbn.simulate``, fresh noise and input each); three models by ``HysteresisModel.fit`` with
default keywords (``seed`` the cell's seed): *measured* (the first log), *joined* (the first
log, and the others with ``x`` NaN), *all* (every log with its state); each scored by the mean
nRMSE of its default mode over two fresh 3000-sample test logs against their true state.

It prints the machine, the date and the command, then a JSON line per cell (the three nRMSEs,
training seconds, EM's rounds of the joined model as ``[round, NLPD, nRMSE, kept]``), then the
geometric means over cells of joined / measured and all / measured, per gain and overall, and
of the training-time ratio joined / measured.

Command::

    pip install ./hbn-py
    python3 benches/unmeasured_logs.py --systems bouc-wen,duhem,preisach --gains 0,1,10 \\
        --seeds 1,2 [--steps 1000] [--extra 2]
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


def score(model: hbn.HysteresisModel, tests: list) -> float:
    return float(np.mean([nrmse(np.asarray(model.estimate(t["u"], t["y"]).x), t["x"]) for t in tests]))


def geo(values: list) -> float:
    return math.exp(sum(math.log(v) for v in values) / len(values)) if values else float("nan")


def main(argv: list | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--systems", default="bouc-wen,duhem,preisach")
    p.add_argument("--gains", default="0,1,10")
    p.add_argument("--seeds", default="1,2")
    p.add_argument("--steps", type=int, default=1000)
    p.add_argument("--extra", type=int, default=2, help="logs without the state")
    p.add_argument("--test-steps", type=int, default=3000)
    a = p.parse_args(argv)
    print(f"# machine: {platform.machine()} {platform.processor() or ''} {platform.node()}")
    print(f"# date: {datetime.datetime.now(datetime.timezone.utc).isoformat(timespec='seconds')}")
    print(f"# command: {' '.join([sys.executable, *sys.argv])}")
    rows = []
    for system in a.systems.split(","):
        for gain in (float(g) for g in a.gains.split(",")):
            for seed in (int(s) for s in a.seeds.split(",")):
                logs = [hbn.simulate(system, a.steps, seed=1000 * seed + i, noise_gain=gain) for i in range(1 + a.extra)]
                tests = [hbn.simulate(system, a.test_steps, seed=900000 + 10 * seed + i, noise_gain=gain) for i in range(2)]
                us, ys = [l["u"] for l in logs], [l["y"] for l in logs]
                t0 = time.perf_counter()
                measured = hbn.HysteresisModel.fit(logs[0]["u"], logs[0]["x"], logs[0]["y"], seed=seed)
                t1 = time.perf_counter()
                xs = [logs[0]["x"]] + [np.full(a.steps, np.nan) for _ in range(a.extra)]
                joined = hbn.HysteresisModel.fit(us, xs, ys, seed=seed)
                t2 = time.perf_counter()
                full = hbn.HysteresisModel.fit(us, [l["x"] for l in logs], ys, seed=seed)
                t3 = time.perf_counter()
                latent = joined.summary.get("latent") or {}
                row = dict(
                    system=system, gain=gain, seed=seed,
                    measured=score(measured, tests), joined=score(joined, tests), all=score(full, tests),
                    seconds=[round(t1 - t0, 1), round(t2 - t1, 1), round(t3 - t2, 1)],
                    rounds=[[r["round"], round(r["nlpd"], 3), round(r["nrmse"], 4), r["improved"]] for r in latent.get("rounds", [])],
                )
                rows.append(row)
                print(json.dumps(row), flush=True)
    for gain in sorted({r["gain"] for r in rows}):
        cell = [r for r in rows if r["gain"] == gain]
        print(f"gain {gain:g}: joined / measured {geo([r['joined'] / r['measured'] for r in cell]):.3f}, "
              f"all / measured {geo([r['all'] / r['measured'] for r in cell]):.3f}")
    print(f"all cells: joined / measured {geo([r['joined'] / r['measured'] for r in rows]):.3f} "
          f"(largest {max(r['joined'] / r['measured'] for r in rows):.3f}), "
          f"all / measured {geo([r['all'] / r['measured'] for r in rows]):.3f}, "
          f"training time joined / measured {geo([r['seconds'][1] / max(r['seconds'][0], 1e-9) for r in rows]):.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
