#!/usr/bin/env python3
"""hbn's vector model against the vector GP-EKF (``vector_gp_ekf.py``) on simulated
multi-signal logs, every state component scored on a test log neither was trained on.

Usage::

    python benches/baselines/vector_run.py --systems finger,arm --gains 0,1,10 --seeds 1,2,3 \\
        [--steps 3000] [--test-steps 2000] [--gp-rows 600] [--keep-logs] --out-dir DIR
    # the Markdown of a saved grid
    python benches/baselines/vector_run.py --table DIR/vector_grid.json

Per system, noise gain and seed ``s`` (the protocol of ``benches/harness`` ``vector_eval``):

* ``hbn simulate --system SYSTEM --seed s`` writes the training log (``--steps`` samples; the
  input and the noise drawn with seed ``s``), and ``--seed 1000+s`` the test log
  (``--test-steps`` samples: a fresh input and noise).
* **hbn**: ``hbn train --log TRAIN --seed s`` with every other flag at its default (the CLI
  finds the inputs, state components and sensors of the log itself), then
  ``hbn estimate --csv`` on the test log in the model's default mode. The CLI, not the wheel:
  it is what a user of the vector model runs (``docs/vector.md``), its training seconds are
  the wall time a user waits, and it scores the binary being released whatever wheel the
  Python environment holds (the wheel only reads the logs, ``hbn.read_mcap``).
* **GP-EKF**: ``vector_gp_ekf.run`` with seed ``s`` on the training log read on its native
  grid, estimating the test log on the same grid (hbn's CSV must be on that grid: checked).
* Both estimates are scored per state component with ``common.score`` (nRMSE, coverage, mean
  NEES, NLPD) on the test log only.

Writes ``DIR/vector_grid.json`` (after every run, so a long grid can be stopped and read) and
``DIR/vector_grid.md``: a header (machine, date, command), a row per run and component with
the ratio hbn / GP-EKF of the nRMSE and the training seconds of each, and per system and gain
the geometric mean of the ratios. The ``hbn`` CLI is ``$HBN_BIN``, else ``target/release/hbn``,
else ``hbn`` on the PATH; BLAS, OpenMP and rayon run on one thread unless the environment says
otherwise (as ``run.py``).
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
import subprocess
import sys
import tempfile
import time
import warnings
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import common  # noqa: E402
import vector_gp_ekf as vg  # noqa: E402
from run import hbn_bin  # noqa: E402

#: Offset of the test log's seed from the training log's (as ``vector_eval``).
TEST_SEED_OFFSET = 1000
#: Default samples of the training and of the test log (as ``vector_eval``).
TRAIN_STEPS, TEST_STEPS = 3000, 2000
#: The two methods, in report order.
METHODS: Tuple[str, ...] = ("hbn", "gp_ekf")
#: Score keys reported per component.
SCORES: Tuple[str, ...] = ("rmse", "nrmse", "coverage_1sigma", "coverage_2sigma", "mean_nees", "nlpd", "samples")


def log_seeds(seed: int) -> Dict[str, int]:
    """Seeds of the simulated logs of run seed ``s``: training ``s``, test ``1000 + s``."""
    return {"train": seed, "test": TEST_SEED_OFFSET + seed}


def simulate(system: str, gain: float, seed: int, workdir: Path, steps: int, test_steps: int) -> Tuple[str, str]:
    """Writes the training and test logs of :func:`log_seeds` with ``hbn simulate`` into
    ``workdir``; returns their paths."""
    exe = hbn_bin()
    workdir.mkdir(parents=True, exist_ok=True)
    out = []
    for name, s, n in (("train.mcap", log_seeds(seed)["train"], steps), ("test.mcap", log_seeds(seed)["test"], test_steps)):
        path = workdir / name
        cmd = [
            exe, "-q", "simulate", "--system", system, "--steps", str(n), "--seed", str(s),
            "--noise-gain", repr(float(gain)), "--out", str(path),
        ]  # fmt: skip
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
        out.append(str(path))
    return out[0], out[1]


def read_estimate_csv(path: Path, dx: int) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Reads ``t`` and the columns ``x{i}``, ``x{i}_std`` of ``hbn estimate --csv``; returns
    ``(t, x (T, dx), x_std (T, dx))`` (an empty cell is NaN)."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))

    def col(name: str) -> np.ndarray:
        if rows and name not in rows[0]:
            raise ValueError(f"{path}: no column {name!r} (a scalar model's CSV?)")
        return np.array([float(r[name]) if r[name] != "" else math.nan for r in rows], dtype=np.float64)

    x = np.column_stack([col(f"x{i}") for i in range(dx)]) if rows else np.empty((0, dx))
    s = np.column_stack([col(f"x{i}_std") for i in range(dx)]) if rows else np.empty((0, dx))
    return col("t") if rows else np.empty(0), x, s


def run_hbn(train_log: str, test_log: str, test: vg.VectorLog, seed: int, workdir: Path) -> Dict[str, Any]:
    """``hbn train`` (default flags, ``--seed``) on ``train_log``, ``hbn estimate --csv`` on
    ``test_log``; returns ``x``, ``x_std`` on ``test``'s grid, the seconds of each command, the
    mode and both commands' summaries. ``ValueError`` if the CSV is not on ``test``'s grid."""
    exe = hbn_bin()
    model, est = workdir / "model.hbn", workdir / "estimate.csv"
    t0 = time.perf_counter()
    tr = subprocess.run(
        [exe, "-q", "train", "--log", train_log, "--seed", str(seed), "--out", str(model)],
        check=True, capture_output=True, text=True,
    )  # fmt: skip
    t1 = time.perf_counter()
    es = subprocess.run(
        [exe, "-q", "estimate", "--model", str(model), "--log", test_log, "--csv", str(est)],
        check=True, capture_output=True, text=True,
    )  # fmt: skip
    t2 = time.perf_counter()
    t, x, s = read_estimate_csv(est, test.x.shape[1])
    grid = np.arange(len(test)) / test.rate
    if t.shape != grid.shape or not np.allclose(t, grid, rtol=0.0, atol=1e-6):
        raise ValueError(f"hbn's estimate has {t.size} samples at t = {t[:3]}..., the test log {grid.size} at {test.rate} Hz")
    mode = re.search(r" with (\S+?);", es.stdout)
    return {
        "x": x,
        "x_std": s,
        "train_seconds": t1 - t0,
        "estimate_seconds": t2 - t1,
        "mode": mode.group(1) if mode else None,
        "train_summary": tr.stdout.strip(),
        "estimate_summary": es.stdout.strip(),
    }


def _json_safe(v: Any) -> Any:
    """NaN/Inf floats become None (JSON has no NaN)."""
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def score_components(x: np.ndarray, x_std: np.ndarray, ref: np.ndarray) -> List[Dict[str, Any]]:
    """``common.score`` of every state component (columns of ``x``, ``x_std``, ``ref``)."""
    return [{k: _json_safe(v) for k, v in common.score(x[:, i], x_std[:, i], ref[:, i]).items()} for i in range(ref.shape[1])]


def run_cell(
    system: str, gain: float, seed: int, workdir: Path, steps: int = TRAIN_STEPS, test_steps: int = TEST_STEPS,
    gp_rows: int = vg.GP_ROWS, log: Any = None,
) -> Dict[str, Any]:  # fmt: skip
    """Simulates, trains and scores both methods for one system, gain and seed. A method that
    fails gets ``{"error": message}`` (and a notice on ``log``) instead of scores."""
    train_log, test_log = simulate(system, gain, seed, workdir, steps, test_steps)
    train, test = vg.read_vector_logs([train_log], test_log)
    du, dx, dy = train[0].dims
    cell: Dict[str, Any] = {
        "system": system, "gain": float(gain), "seed": seed, "log_seeds": log_seeds(seed),
        "dims": {"du": du, "dx": dx, "dy": dy}, "rate": train[0].rate, "n_train": len(train[0]), "n_test": len(test),
    }  # fmt: skip
    results: Dict[str, Dict[str, Any]] = {}
    try:
        results["hbn"] = run_hbn(train_log, test_log, test, seed, workdir)
    except Exception as e:  # a failing method must not hide the other's figures
        detail = getattr(e, "stderr", None)
        results["hbn"] = {"error": f"{type(e).__name__}: {e}" + (f": {detail.strip()}" if detail else "")}
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # sklearn's ConvergenceWarning about bounds
            results["gp_ekf"] = vg.run(train, test, seed=seed, rows=gp_rows)
    except Exception as e:
        results["gp_ekf"] = {"error": f"{type(e).__name__}: {e}"}
    for name in METHODS:
        r = results[name]
        if "error" in r:
            print(f"{system} gain {gain:g} seed {seed}: {name} failed: {r['error']}", file=log or sys.stderr)
            cell[name] = r
            continue
        cell[name] = {k: v for k, v in r.items() if k not in ("x", "x_std")}
        cell[name]["components"] = score_components(r["x"], r["x_std"], test.x)
    cell["ratio_nrmse"] = ratios(cell)
    return cell


def ratios(cell: Mapping[str, Any]) -> List[Optional[float]]:
    """Per component, hbn's nRMSE over the GP-EKF's (``None`` where either is missing)."""
    h, g = cell.get("hbn", {}), cell.get("gp_ekf", {})
    if "components" not in h or "components" not in g:
        return [None] * int(cell["dims"]["dx"])
    out: List[Optional[float]] = []
    for a, b in zip(h["components"], g["components"]):
        ok = a["nrmse"] is not None and b["nrmse"] is not None and b["nrmse"] > 0
        out.append(a["nrmse"] / b["nrmse"] if ok else None)
    return out


def summarise(runs: Sequence[Mapping[str, Any]]) -> List[Dict[str, Any]]:
    """Per system and gain: the geometric mean of the ratios over seeds and components, how
    many components hbn is the more accurate on, the mean 2-sigma coverage of each method and
    the mean training seconds of each."""
    keys: List[Tuple[str, float]] = []
    for r in runs:
        if (r["system"], r["gain"]) not in keys:
            keys.append((r["system"], r["gain"]))
    out = []
    for system, gain in keys:
        cell = [r for r in runs if r["system"] == system and r["gain"] == gain]
        rs = [q for r in cell for q in r["ratio_nrmse"] if q is not None and q > 0]
        row: Dict[str, Any] = {
            "system": system, "gain": gain, "runs": len(cell), "components": len(rs),
            "geo_mean_ratio": float(np.exp(np.mean(np.log(rs)))) if rs else None,
            "hbn_better": sum(q < 1.0 for q in rs),
        }  # fmt: skip
        for m in METHODS:
            cov = [c["coverage_2sigma"] for r in cell if "components" in r[m] for c in r[m]["components"] if c["coverage_2sigma"] is not None]
            secs = [r[m]["train_seconds"] for r in cell if "train_seconds" in r[m]]
            row[f"{m}_coverage_2sigma"] = float(np.mean(cov)) if cov else None
            row[f"{m}_train_seconds"] = float(np.mean(secs)) if secs else None
        out.append(row)
    return out


def machine() -> Dict[str, str]:
    """The machine a grid ran on: ``uname``, the CPU model and the CPUs the process may use."""
    cpu = platform.processor() or "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    u = platform.uname()
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 0)
    return {"uname": f"{u.system} {u.release} {u.machine}", "cpu": f"{cpu} ({cpus} CPUs usable)"}


def hbn_version() -> str:
    """The ``hbn`` CLI's path and ``--version`` line."""
    exe = hbn_bin()
    v = subprocess.run([exe, "--version"], capture_output=True, text=True, check=False).stdout.strip()
    return f"{exe} ({v or 'version unknown'})"


def _fmt(v: Any, spec: str) -> str:
    return "-" if v is None else format(v, spec)


def markdown(doc: Mapping[str, Any]) -> str:
    """The Markdown report of a grid document (:func:`grid`'s JSON)."""
    h = doc["header"]
    out = [
        "# hbn vector model / vector GP-EKF",
        "",
        f"- machine: {h['machine']['uname']}, {h['machine']['cpu']}",
        f"- date: {h['date']}",
        f"- command: `{h['command']}`",
        f"- hbn: {h['hbn']}; threads: {h['threads']}",
        f"- protocol: training log {doc['steps']} samples (seed s), test log {doc['test_steps']} samples "
        f"(seed {TEST_SEED_OFFSET} + s); hbn: `hbn train --seed s` (other flags default), `hbn estimate --csv`; "
        f"GP-EKF: {doc['gp_rows']} rows per GP; scored on the test log only",
        "",
        "| system | gain | seed | hbn mode | comp. | nRMSE hbn | nRMSE GP-EKF | hbn / GP-EKF | cov. 2σ hbn "
        "| cov. 2σ GP-EKF | NEES hbn | NEES GP-EKF | NLPD hbn | NLPD GP-EKF | train s hbn | train s GP-EKF |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in doc["runs"]:
        hb, gp = r["hbn"], r["gp_ekf"]
        for i in range(r["dims"]["dx"]):
            a = hb["components"][i] if "components" in hb else {}
            b = gp["components"][i] if "components" in gp else {}
            out.append(
                f"| {r['system']} | {r['gain']:g} | {r['seed']} | {hb.get('mode') or '-'} | x{i} "
                f"| {_fmt(a.get('nrmse'), '.4f')} | {_fmt(b.get('nrmse'), '.4f')} "
                f"| {_fmt(r['ratio_nrmse'][i], '.2f')} "
                f"| {_fmt(a.get('coverage_2sigma'), '.3f')} | {_fmt(b.get('coverage_2sigma'), '.3f')} "
                f"| {_fmt(a.get('mean_nees'), '.3g')} | {_fmt(b.get('mean_nees'), '.3g')} "
                f"| {_fmt(a.get('nlpd'), '.3f')} | {_fmt(b.get('nlpd'), '.3f')} "
                f"| {_fmt(hb.get('train_seconds'), '.1f')} | {_fmt(gp.get('train_seconds'), '.1f')} |"
            )
    out += [
        "",
        "| system | gain | runs | components | geo. mean hbn / GP-EKF | hbn more accurate | mean cov. 2σ hbn "
        "| mean cov. 2σ GP-EKF | mean train s hbn | mean train s GP-EKF |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for s in doc.get("summary", []):
        out.append(
            f"| {s['system']} | {s['gain']:g} | {s['runs']} | {s['components']} | {_fmt(s['geo_mean_ratio'], '.2f')} "
            f"| {s['hbn_better']} of {s['components']} "
            f"| {_fmt(s['hbn_coverage_2sigma'], '.3f')} | {_fmt(s['gp_ekf_coverage_2sigma'], '.3f')} "
            f"| {_fmt(s['hbn_train_seconds'], '.1f')} | {_fmt(s['gp_ekf_train_seconds'], '.1f')} |"
        )
    errors = [f"- {r['system']} gain {r['gain']:g} seed {r['seed']}: {m}: {r[m]['error']}" for r in doc["runs"] for m in METHODS if "error" in r[m]]
    if errors:
        out += ["", "Failures:", ""] + errors
    return "\n".join(out) + "\n"


def grid(
    systems: Sequence[str], gains: Sequence[float], seeds: Sequence[int], out_dir: Path,
    steps: int = TRAIN_STEPS, test_steps: int = TEST_STEPS, gp_rows: int = vg.GP_ROWS,
    keep_logs: bool = False, command: Optional[str] = None, log: Any = None,
) -> Dict[str, Any]:  # fmt: skip
    """Runs :func:`run_cell` for every system x gain x seed, writing ``out_dir/vector_grid.json``
    after every run and ``out_dir/vector_grid.md`` at the end; returns the JSON content. With
    ``keep_logs`` the logs, models and estimates stay in ``out_dir/logs/``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    doc: Dict[str, Any] = {
        "header": {
            "machine": machine(),
            "date": datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
            "command": command or " ".join([Path(sys.executable).name] + sys.argv),
            "threads": ", ".join(f"{v}={os.environ.get(v, '')}" for v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "RAYON_NUM_THREADS")),
            "hbn": hbn_version(),
        },
        "systems": list(systems), "gains": [float(g) for g in gains], "seeds": [int(s) for s in seeds],
        "steps": steps, "test_steps": test_steps, "gp_rows": gp_rows, "runs": [],
    }  # fmt: skip
    for system in systems:
        for gain in gains:
            for seed in seeds:
                t0 = time.perf_counter()
                with tempfile.TemporaryDirectory(prefix="hbn-vector-") as tmp:
                    wd = out_dir / "logs" / f"{system}-g{gain:g}-s{seed}" if keep_logs else Path(tmp)
                    cell = run_cell(system, gain, seed, wd, steps, test_steps, gp_rows, log)
                doc["runs"].append(cell)
                r = ", ".join(_fmt(q, ".2f") for q in cell["ratio_nrmse"])
                print(f"[{system} gain {gain:g} seed {seed}: {time.perf_counter() - t0:.1f} s; hbn / GP-EKF nRMSE {r}]", file=log or sys.stderr)
                doc["summary"] = summarise(doc["runs"])
                doc["total_seconds"] = time.perf_counter() - t_start
                (out_dir / "vector_grid.json").write_text(json.dumps(doc, indent=1))
    (out_dir / "vector_grid.md").write_text(markdown(doc))
    return doc


def _csv(s: str, kind: type) -> List[Any]:
    """``"a,b"`` -> ``[kind(a), kind(b)]``."""
    return [kind(x) for x in s.split(",") if x.strip()]


def main(argv: Optional[Sequence[str]] = None) -> int:
    """The command line (see the module docstring); returns the exit code."""
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--systems", default="finger,arm", help="multi-signal systems of `hbn simulate` (comma-separated)")
    ap.add_argument("--gains", default="0,1,10", help="noise gains (comma-separated)")
    ap.add_argument("--seeds", default="1,2,3", help="run seeds s (comma-separated): training log seed s, test log 1000 + s")
    ap.add_argument("--steps", type=int, default=TRAIN_STEPS, help="samples of the training log")
    ap.add_argument("--test-steps", type=int, default=TEST_STEPS, help="samples of the test log")
    ap.add_argument("--gp-rows", type=int, default=vg.GP_ROWS, help="rows per scikit-learn GP")
    ap.add_argument("--keep-logs", action="store_true", help="keep logs, models and estimates in OUT_DIR/logs")
    ap.add_argument("--out-dir", type=Path, default=Path("vector-grid"), help="where vector_grid.json and .md go")
    ap.add_argument("--table", type=Path, metavar="GRID_JSON", help="print the Markdown of a saved vector_grid.json and exit")
    a = ap.parse_args(argv)
    if a.table is not None:
        print(markdown(json.loads(a.table.read_text())), end="")
        return 0
    command = " ".join(["python", "benches/baselines/vector_run.py"] + list(sys.argv[1:] if argv is None else argv))
    doc = grid(_csv(a.systems, str), _csv(a.gains, float), _csv(a.seeds, int), a.out_dir, steps=a.steps,
               test_steps=a.test_steps, gp_rows=a.gp_rows, keep_logs=a.keep_logs, command=command)  # fmt: skip
    print(markdown(doc), end="")
    print(f"{len(doc['runs'])} runs in {doc.get('total_seconds', 0.0):.0f} s; wrote {a.out_dir / 'vector_grid.json'} and {a.out_dir / 'vector_grid.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
