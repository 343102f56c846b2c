#!/usr/bin/env python3
"""What a slow, frame-dropping state camera costs hbn: accuracy and training time of models
trained on logs whose state comes from a camera slower than the sensor, against the same
logs with the state at every sample.

What it measures. For every simulator x noise gain x seed (a *cell*) and every camera
``RATE[:DROP]`` of ``--cameras`` (Hz, fraction of frames dropped):

* ``hbn simulate --system SYSTEM --steps STEPS --seed s --noise-gain g --state-rate RATE
  [--state-drop DROP]`` writes the training log: input and sensor at 100 Hz, the state as the
  camera records it (frames on the camera's own clock, each the true state at its time);
* ``hbn train --log TRAIN --out model.hbn`` with every other flag at its default, timed (wall
  seconds, the time a user waits);
* ``hbn simulate ... --seed 1000+s --steps TEST_STEPS`` writes the test log (a fresh input and
  noise, the state at every sample), one per cell, shared by the cameras;
* ``hbn estimate --model model.hbn --log TEST --csv`` (the model's default mode) is scored
  against the test log's true state at every 100 Hz sample: nRMSE, RMSE / (max - min) of the
  true state, and the share of samples within 2 standard deviations (``common.nrmse`` and
  ``common.calibration`` of ``benches/baselines``). A multi-signal system (``finger``,
  ``arm``: a vector model, its state a topic with a field per component, the camera filming
  every component at once) is scored per component, and its cell's nRMSE and coverage are the
  means over the components.

A camera ``100@SEED`` trains the reference's log again with ``hbn train --seed SEED`` (another
optimiser start): two models as well informed as each other, whose ratio is the spread that a
single cell's ratio carries before any frame is missing.

It prints the machine, the date, the command and the ``hbn`` binary, then a row per cell and
camera (system, gain, seed, camera, frames kept, nRMSE, 2-sigma coverage, training seconds),
then per camera the geometric mean over cells of nRMSE(camera) / nRMSE(reference), the largest
cell ratio, the number of cells above 1.2 and the mean over cells of the training-time ratio. The reference is the camera at
the simulator's rate without drops (``100``, the state at every sample), which ``--cameras``
must hold. ``--json FILE`` writes the header, the rows and the summary.

Command (the default grid: 3 systems x 3 gains x 3 seeds x 3 cameras, 81 trainings)::

    cargo build --release -p hbn-cli
    nice python3 benches/slow_camera.py [--systems bouc-wen,duhem,preisach] [--gains 0,1,10] \\
        [--seeds 1,2,3] [--steps 3000] [--test-steps 3000] [--cameras 100,30:0.1,10] \\
        [--hbn target/release/hbn] [--json rows.json]

Needs numpy and the hbn wheel (``pip install ./hbn-py``), which reads the test log's true state
(``hbn.read_mcap`` through ``common.read_log``); everything else runs through the ``hbn``
binary. Logs, models and estimates live in a temporary directory, removed at the end. BLAS,
OpenMP and rayon run on one thread unless the environment says otherwise (as
``benches/baselines/run.py``), so the seconds are comparable on a shared machine.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "RAYON_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import csv
import json
import math
import platform
import re
import shlex
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benches" / "baselines"))

import common  # noqa: E402
import vector_gp_ekf  # noqa: E402

#: The simulator's rate (Hz): `hbn simulate`'s default, the rate of the sensor and the input.
SIM_RATE = 100.0
#: Offset of the test log's seed from the training log's.
TEST_SEED_OFFSET = 1000
#: Columns of the per-cell table.
TABLE_HEADER = "| system | gain | seed | camera | frames kept | nRMSE | cov. 2σ | train s |"


@dataclass(frozen=True)
class Camera:
    """A camera of ``--cameras``: ``RATE[:DROP][@SEED]``."""

    rate: float
    drop: float
    label: str
    #: ``hbn train --seed`` (``None``: its default).
    train_seed: Optional[int] = None

    @property
    def is_reference(self) -> bool:
        """The state at every sample: the simulator's rate, nothing dropped, trained with the
        default seed."""
        return self.rate == SIM_RATE and self.drop == 0.0 and self.train_seed is None


def parse_camera(text: str) -> Camera:
    """``"30:0.1"`` -> 30 Hz dropping 10% of its frames; ``"10"`` -> 10 Hz, nothing dropped;
    ``"100@2"`` -> the state at every sample, the model trained with ``hbn train --seed 2``
    (two equally informed models: the spread of the ratio itself)."""
    spec, at, seed_s = text.strip().partition("@")
    rate_s, _, drop_s = spec.partition(":")
    try:
        rate, drop = float(rate_s), float(drop_s) if drop_s else 0.0
        train_seed = int(seed_s) if at else None
    except ValueError:
        raise ValueError(f"camera {text!r}: expected RATE[:DROP][@SEED], e.g. 30:0.1 or 100@2") from None
    if train_seed is not None and train_seed < 0:
        raise ValueError(f"camera {text!r}: the training seed must be >= 0")
    if not (math.isfinite(rate) and 0.0 < rate <= SIM_RATE):
        raise ValueError(f"camera {text!r}: the rate must be in (0, {SIM_RATE:g}] Hz")
    if not 0.0 <= drop < 1.0:
        raise ValueError(f"camera {text!r}: the drop fraction must be in [0, 1)")
    return Camera(rate, drop, text.strip(), train_seed)


def run(cmd: Sequence[str]) -> subprocess.CompletedProcess:
    """Runs ``cmd``; a failure raises ``RuntimeError`` with its stderr."""
    p = subprocess.run(list(cmd), capture_output=True, text=True, check=False)
    if p.returncode != 0:
        raise RuntimeError(f"`{shlex.join(cmd)}` failed ({p.returncode}): {p.stderr.strip()}")
    return p


def simulate(hbn: str, system: str, gain: float, seed: int, steps: int, out: Path, camera: Optional[Camera]) -> Dict[str, Any]:
    """``hbn simulate`` into ``out``; with a camera, returns the frames it kept and took."""
    cmd = [hbn, "simulate", "--system", system, "--steps", str(steps), "--seed", str(seed), "--noise-gain", repr(float(gain)), "--out", str(out)]
    if camera is not None:
        cmd += ["--state-rate", repr(camera.rate)] + (["--state-drop", repr(camera.drop)] if camera.drop > 0.0 else [])
    stdout = run(cmd).stdout
    frames = re.search(r"(\d+) of (\d+) frames kept", stdout)
    return {"frames_kept": int(frames.group(1)), "frames_taken": int(frames.group(2))} if frames else {}


def read_estimate_csv(path: Path) -> Dict[str, np.ndarray]:
    """The columns ``t``, ``x``, ``x_std`` of ``hbn estimate --csv``; for a vector model's
    (``x0``, ``x0_std``, ``x1``, ...), ``x`` and ``x_std`` are ``(T, dx)``."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))

    def col(name: str) -> np.ndarray:
        return np.array([float(r[name]) if r[name] != "" else math.nan for r in rows], dtype=np.float64)

    names = list(rows[0]) if rows else []
    if "x" in names or not rows:
        return {k: col(k) for k in ("t", "x", "x_std")}
    dx = sum(1 for n in names if re.fullmatch(r"x\d+", n))
    return {
        "t": col("t"),
        "x": np.column_stack([col(f"x{i}") for i in range(dx)]),
        "x_std": np.column_stack([col(f"x{i}_std") for i in range(dx)]),
    }


def read_truth(system: str, test_log: Path) -> Tuple[np.ndarray, float]:
    """The true state of a test log at every sample (``(T,)``, or ``(T, dx)`` for a
    multi-signal system) and its rate."""
    import hbn

    if system in hbn.MULTI_SYSTEMS:
        _, test = vector_gp_ekf.read_vector_logs([str(test_log)], str(test_log))
        return test.x, test.rate
    log = common.read_log(str(test_log), common.DEFAULT_PATHS)
    return log.x, log.rate


def score(x: np.ndarray, x_std: np.ndarray, truth: np.ndarray) -> Tuple[float, float]:
    """nRMSE and 2-sigma coverage; for a vector state the means over its components."""
    if truth.ndim == 1:
        return common.nrmse(x, truth), common.calibration(x, x_std, truth)["coverage_2sigma"]
    per = [score(x[:, i], x_std[:, i], truth[:, i]) for i in range(truth.shape[1])]
    return float(np.mean([p[0] for p in per])), float(np.mean([p[1] for p in per]))


def train_and_score(
    hbn: str, train_log: Path, test_log: Path, truth: Tuple[np.ndarray, float], workdir: Path, train_seed: Optional[int] = None
) -> Dict[str, Any]:
    """``hbn train`` (defaults, or ``--seed train_seed``) on ``train_log``, ``hbn estimate
    --csv`` on ``test_log``, scored against ``truth``: ``nrmse``, ``coverage_2sigma``,
    ``train_seconds``, the mode and the training summary."""
    model, est = workdir / "model.hbn", workdir / "estimate.csv"
    seed_args = [] if train_seed is None else ["--seed", str(train_seed)]
    t0 = time.perf_counter()
    tr = run([hbn, "train", "--log", str(train_log), "--out", str(model), *seed_args])
    train_seconds = time.perf_counter() - t0
    es = run([hbn, "-q", "estimate", "--model", str(model), "--log", str(test_log), "--csv", str(est)])
    e = read_estimate_csv(est)
    x_true, rate = truth
    grid = np.arange(len(x_true)) / rate
    if e["t"].shape != grid.shape or not np.allclose(e["t"], grid, rtol=0.0, atol=1e-6):
        raise ValueError(f"the estimate has {e['t'].size} samples, the test log {grid.size} at {rate:g} Hz")
    mode = re.search(r"\n\s+(\S+) \(the model's default mode\)", "\n" + es.stdout)
    nrmse, coverage = score(e["x"], e["x_std"], x_true)
    return {
        "nrmse": nrmse,
        "coverage_2sigma": coverage,
        "train_seconds": train_seconds,
        "mode": mode.group(1) if mode else None,
        "train_summary": tr.stdout.strip(),
    }


def _fmt(v: Any, spec: str) -> str:
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else format(v, spec)


def table_row(r: Dict[str, Any]) -> str:
    """One row of the per-cell table."""
    frames = f"{r['frames_kept']} of {r['frames_taken']}" if "frames_kept" in r else "-"
    tail = f" {r['error']}" if "error" in r else ""
    return (
        f"| {r['system']} | {r['gain']:g} | {r['seed']} | {r['camera']} | {frames} | {_fmt(r.get('nrmse'), '.4f')} "
        f"| {_fmt(r.get('coverage_2sigma'), '.3f')} | {_fmt(r.get('train_seconds'), '.1f')} |{tail}"
    )


def summarise(rows: Sequence[Dict[str, Any]], cameras: Sequence[Camera]) -> List[Dict[str, Any]]:
    """Per camera, over the cells where it and the reference both scored: the geometric mean
    and the largest of nRMSE(camera) / nRMSE(reference), how many cells exceed 1.2, and the
    mean of the training-time ratio."""
    ref = next(c for c in cameras if c.is_reference)
    by_cell: Dict[tuple, Dict[str, Dict[str, Any]]] = {}
    for r in rows:
        by_cell.setdefault((r["system"], r["gain"], r["seed"]), {})[r["camera"]] = r
    out = []
    for cam in cameras:
        ratios, time_ratios = [], []
        for cell in by_cell.values():
            a, b = cell.get(cam.label), cell.get(ref.label)
            if a is None or b is None or "error" in a or "error" in b:
                continue
            if a["nrmse"] > 0 and b["nrmse"] > 0 and math.isfinite(a["nrmse"] / b["nrmse"]):
                ratios.append(a["nrmse"] / b["nrmse"])
            if b["train_seconds"] > 0:
                time_ratios.append(a["train_seconds"] / b["train_seconds"])
        out.append({
            "camera": cam.label, "rate": cam.rate, "drop": cam.drop, "cells": len(ratios),
            "geo_mean_nrmse_ratio": float(np.exp(np.mean(np.log(ratios)))) if ratios else None,
            "max_nrmse_ratio": max(ratios) if ratios else None,
            "cells_above_1_2": sum(r > 1.2 for r in ratios),
            "mean_train_time_ratio": float(np.mean(time_ratios)) if time_ratios else None,
        })  # fmt: skip
    return out


def json_safe(v: Any) -> Any:
    """NaN and infinite floats become ``None`` (JSON has no NaN), recursively."""
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, dict):
        return {k: json_safe(x) for k, x in v.items()}
    if isinstance(v, list):
        return [json_safe(x) for x in v]
    return v


def machine() -> str:
    """The machine: ``uname``, the CPU model and the CPUs this process may use."""
    cpu = platform.processor() or "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    u = platform.uname()
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 0)
    return f"{u.system} {u.release} {u.machine}, {cpu} ({cpus} CPUs usable)"


def _csv(text: str, kind: type) -> List[Any]:
    return [kind(x) for x in text.split(",") if x.strip()]


def main(argv: Optional[Sequence[str]] = None) -> int:
    """The command line (see the module docstring); returns the exit code."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--systems", default="bouc-wen,duhem,preisach", help="systems of `hbn simulate --help` (scalar or multi-signal), comma-separated")
    ap.add_argument("--gains", default="0,1,10", help="noise gains, comma-separated")
    ap.add_argument("--seeds", default="1,2,3", help="seeds, comma-separated (the test log's seed is 1000 + seed)")
    ap.add_argument("--steps", type=int, default=3000, help="samples of a training log (100 Hz)")
    ap.add_argument("--test-steps", type=int, default=3000, help="samples of a test log (100 Hz)")
    ap.add_argument(
        "--cameras",
        default="100,30:0.1,10",
        help="cameras RATE[:DROP][@SEED], comma-separated; must hold 100 (the reference); 100@SEED trains the reference's log again with `hbn train --seed SEED`",
    )
    ap.add_argument("--hbn", default=str(REPO / "target" / "release" / "hbn"), help="the hbn binary (default: target/release/hbn)")
    ap.add_argument("--json", type=Path, default=None, metavar="FILE", help="write the header, the rows and the summary as JSON")
    a = ap.parse_args(argv)
    try:
        cameras = [parse_camera(c) for c in a.cameras.split(",") if c.strip()]
    except ValueError as e:
        ap.error(f"--cameras: {e}")
    if not any(c.is_reference for c in cameras):
        ap.error(f"--cameras must hold {SIM_RATE:g} (the state at every sample), the reference of the ratios")
    if len({c.label for c in cameras}) != len(cameras):
        ap.error("--cameras names a camera twice")
    if not Path(a.hbn).is_file():
        ap.error(f"--hbn {a.hbn}: no such file; build it with `cargo build --release -p hbn-cli`")
    systems, gains, seeds = _csv(a.systems, str), _csv(a.gains, float), _csv(a.seeds, int)
    version = run([a.hbn, "--version"]).stdout.strip()
    header = {
        "machine": machine(),
        "date": datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "command": shlex.join([Path(sys.executable).name] + list(sys.argv if argv is None else ["benches/slow_camera.py", *argv])),
        "hbn": f"{a.hbn} ({version})",
        "threads": ", ".join(f"{v}={os.environ.get(v, '')}" for v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "RAYON_NUM_THREADS")),
        "protocol": {"systems": systems, "gains": gains, "seeds": seeds, "steps": a.steps, "test_steps": a.test_steps,
                     "cameras": [c.label for c in cameras], "sim_rate": SIM_RATE, "test_seed_offset": TEST_SEED_OFFSET},
    }  # fmt: skip
    print("# hbn trained from a slow camera")
    print(f"- machine: {header['machine']}")
    print(f"- date: {header['date']}")
    print(f"- command: `{header['command']}`")
    print(f"- hbn: {header['hbn']}; threads: {header['threads']}")
    print(
        f"- protocol: training log {a.steps} samples at {SIM_RATE:g} Hz (seed s, the state from the camera), "
        f"`hbn train` with default flags; test log {a.test_steps} samples (seed {TEST_SEED_OFFSET} + s, the state "
        "at every sample), scored at every sample in the model's default mode"
    )
    print()
    print(TABLE_HEADER)
    print("|---|---|---|---|---|---|---|---|", flush=True)
    rows: List[Dict[str, Any]] = []
    t_start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="hbn-slow-camera-") as tmp:
        wd = Path(tmp)
        for system in systems:
            for gain in gains:
                for seed in seeds:
                    test_log = wd / "test.mcap"
                    simulate(a.hbn, system, gain, TEST_SEED_OFFSET + seed, a.test_steps, test_log, None)
                    truth = read_truth(system, test_log)
                    for cam in cameras:
                        row: Dict[str, Any] = {"system": system, "gain": gain, "seed": seed, "camera": cam.label, "rate": cam.rate, "drop": cam.drop, "train_seed": cam.train_seed}
                        try:
                            train_log = wd / "train.mcap"
                            row.update(simulate(a.hbn, system, gain, seed, a.steps, train_log, cam))
                            row.update(train_and_score(a.hbn, train_log, test_log, truth, wd, cam.train_seed))
                        except (RuntimeError, ValueError, OSError) as e:  # one failure must not hide the others
                            row["error"] = str(e)
                        rows.append(row)
                        print(table_row(row), flush=True)
    summary = summarise(rows, cameras)
    print()
    print("| camera | cells | geo. mean nRMSE / nRMSE(100 Hz) | largest cell ratio | cells above 1.2 | mean train-time ratio |")
    print("|---|---|---|---|---|---|")
    for s in summary:
        print(
            f"| {s['camera']} | {s['cells']} | {_fmt(s['geo_mean_nrmse_ratio'], '.3f')} | {_fmt(s['max_nrmse_ratio'], '.3f')} "
            f"| {s['cells_above_1_2']} | {_fmt(s['mean_train_time_ratio'], '.2f')} |"
        )
    failed = sum("error" in r for r in rows)
    print(f"\n{len(rows)} runs ({failed} failed) in {time.perf_counter() - t_start:.0f} s")
    if a.json is not None:
        a.json.write_text(json.dumps(json_safe({"header": header, "rows": rows, "summary": summary}), indent=1, allow_nan=False))
        print(f"wrote {a.json}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
