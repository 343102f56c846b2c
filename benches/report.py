#!/usr/bin/env python3
"""Regenerates ``docs/accuracy.md`` and ``docs/performance.md`` from a fresh run.

Usage::

    python3 benches/report.py --quick                  # both pages, about 10 minutes on 2 cores
    python3 benches/report.py --full                   # both pages, the whole grid (about an hour)
    python3 benches/report.py --quick --raw /tmp/runs  # also keep the raw runs (JSON, CSV)
    python3 benches/report.py --quick --only performance

Each page starts with the machine (CPU model, cores, OS), the date, the git commit and the
command that wrote it. Every figure is measured in the same run as the baseline it is compared
with.

``docs/accuracy.md``:

* the thesis' simulation experiment (``hbn experiment``: Maxwell-slip and generalised PI, one
  training input repeated 10 times, a fresh test input), nRMSE per mode and noise gain, with the
  calibration of the default mode;
* hbn with its default settings against the baselines of ``benches/baselines`` (the
  scikit-learn GP-EKF, the NARX network; the LSTM when torch is installed, otherwise left out
  with a note) and the floor under causal estimation (``hbn.oracle_estimate``), on the same
  simulated MCAP logs (``benches/baselines/run.py --grid``), as ratios, and the calibration of
  each.

``docs/performance.md``:

* the estimator step in Rust per mode (harness program ``step_time``) for the default model
  with exact GPs and with sparse GPs of 64 inducing points, against the numpy implementation of
  the same EKF (``benches/numpy_filter.py``) on the same model and log;
* the step called from Python (``HysteresisModel.estimate``) against the same numpy filter;
* training: one GP fit against scikit-learn (``benches/compare_sklearn.py``), and ``hbn train``
  with its defaults against the fit of the scikit-learn GP-EKF baseline on the same logs;
* firmware: model data (flash) and work memory (RAM) of ``hbn export --format c`` in f32
  against f64, for the default model and for a sparse model (``--inducing 32``, EKF).

Modes:

* ``--quick``: the thesis experiment and the grid on two simulators (bouc-wen and maxwell-slip
  for the grid) at noise gains 0, 1 and 10, seed 1; fewer timing repetitions. Within 10 minutes
  on a 2-core machine.
* ``--full``: the thesis experiment at noise gains 0, 0.5, 1, 2, 5 and 10, seeds 1-3; the grid
  on all six simulators (bouc-wen, duhem, preisach, soft-actuator, maxwell-slip,
  generalized-pi) at noise gains 0, 1 and 10, seeds 1-3; more repetitions.

Requirements: Rust (cargo), Python 3 and pip. When the Python that runs the script cannot
import numpy, scikit-learn and the wheel, the script creates ``target/report-venv``, installs
them there (the wheel built from this checkout) and runs itself in it; torch (the LSTM) is
used when installed there. Cargo: the script first builds ``target/release/hbn`` and the harness programs
(``cargo build --release -p hbn-cli -p hbn-harness``; ``--no-build`` uses them as they are).
Every program runs on one thread (BLAS, OpenMP and rayon; set ``RAYON_NUM_THREADS`` etc. to
change it), so the times are comparable and the run leaves a core to the rest of a shared
machine; the thesis experiment runs beside the grid, as a second process, and the performance
measurements run alone.

Raw runs (JSON, CSV and the trained model files) go to ``--raw DIR`` only, a directory that
must lie outside the repository's tracked tree; without ``--raw`` they live in a temporary
directory that is deleted at the end.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "RAYON_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import datetime
import json
import math
import platform
import re
import shlex
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benches"))
sys.path.insert(0, str(ROOT / "benches" / "baselines"))
#: The private environment the script runs itself in when the Python that started it lacks
#: numpy, scikit-learn or the wheel (a fresh clone): like scripts/test.sh's.
REPORT_VENV = ROOT / "target" / "report-venv"


def _ensure_environment() -> None:
    """Re-runs this script in ``target/report-venv`` (created if missing, with numpy,
    scikit-learn and the wheel of this checkout built and installed) when the running Python
    cannot import numpy, scikit-learn and hbn, so that ``python3 benches/report.py --quick``
    works on a fresh clone with only Rust, Python and pip. The wheel is reinstalled from the
    checkout on every such run, so the report measures the code it is run from."""
    try:
        import hbn  # noqa: F401
        import numpy  # noqa: F401
        import sklearn  # noqa: F401

        return
    except ImportError as e:
        missing = e.name
    venv_python = REPORT_VENV / "bin" / "python"
    if Path(sys.prefix).resolve() == REPORT_VENV.resolve():
        sys.exit(f"benches/report.py: {missing} is not importable in {REPORT_VENV}: remove it and run again")
    print(f"[report] {missing} is not importable here: running in {REPORT_VENV} "
          "(numpy, scikit-learn and the wheel of this checkout; the first build takes minutes)",
          flush=True)
    if not venv_python.exists():
        subprocess.run([sys.executable, "-m", "venv", str(REPORT_VENV)], check=True)
    pip = [str(venv_python), "-m", "pip", "install", "--quiet"]
    subprocess.run(pip + ["numpy", "scikit-learn"], check=True)
    subprocess.run(pip + ["--force-reinstall", "--no-deps", str(ROOT / "hbn-py")], check=True)
    os.execv(str(venv_python), [str(venv_python), str(Path(__file__).resolve()), *sys.argv[1:]])


if __name__ == "__main__":
    _ensure_environment()

import numpy as np  # noqa: E402

SIMULATORS = ("bouc-wen", "duhem", "preisach", "soft-actuator", "maxwell-slip", "generalized-pi")
THESIS_SYSTEMS = ("maxwell-slip", "generalized-pi")


@dataclass(frozen=True)
class Plan:
    """What one mode of the script runs."""

    name: str
    thesis_gains: Tuple[float, ...]
    thesis_seeds: Tuple[int, ...]
    grid_systems: Tuple[str, ...]
    grid_gains: Tuple[float, ...]
    grid_seeds: Tuple[int, ...]
    step_passes: int
    step_log: int  # samples of the test log the step is timed on
    numpy_steps: int  # samples the numpy filter runs (it is slow)
    fit_sizes: Tuple[int, ...]
    fit_repeats: int


QUICK = Plan(
    name="quick",
    thesis_gains=(0.0, 1.0, 10.0),
    thesis_seeds=(1,),
    grid_systems=("bouc-wen", "maxwell-slip"),
    grid_gains=(0.0, 1.0, 10.0),
    grid_seeds=(1,),
    step_passes=5,
    step_log=2000,
    numpy_steps=1000,
    fit_sizes=(1000,),
    fit_repeats=1,
)
FULL = Plan(
    name="full",
    thesis_gains=(0.0, 0.5, 1.0, 2.0, 5.0, 10.0),
    thesis_seeds=(1, 2, 3),
    grid_systems=SIMULATORS,
    grid_gains=(0.0, 1.0, 10.0),
    grid_seeds=(1, 2, 3),
    step_passes=15,
    step_log=5000,
    numpy_steps=5000,
    fit_sizes=(1000, 2000),
    fit_repeats=3,
)


# ------------------------------------------------------------------------------------------------
# Helpers
# ------------------------------------------------------------------------------------------------


def say(msg: str) -> None:
    """Progress on stderr, with the time of day."""
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def run(cmd: Sequence[str], **kw: Any) -> subprocess.CompletedProcess:
    """Runs ``cmd`` (checked), its stdout captured as text."""
    return subprocess.run([str(c) for c in cmd], check=True, capture_output=True, text=True, **kw)


def exe(name: str) -> Path:
    """A program of the release target directory."""
    target = Path(os.environ.get("CARGO_TARGET_DIR", str(ROOT / "target")))
    return target / "release" / name


def fmt(v: Optional[float], spec: str = ".4f") -> str:
    """A number, or ``-`` for a missing one."""
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    return format(v, spec)


def mean_sd(vals: Sequence[float], spec: str = ".4f") -> str:
    """``mean +- sd`` over several values, the value alone for one."""
    vals = [v for v in vals if v is not None and math.isfinite(v)]
    if not vals:
        return "-"
    if len(vals) == 1:
        return format(vals[0], spec)
    return f"{format(statistics.fmean(vals), spec)} +- {format(statistics.pstdev(vals), spec)}"


def geomean(vals: Iterable[float]) -> Optional[float]:
    """Geometric mean of the positive finite values (``None`` if there are none)."""
    v = [x for x in vals if x is not None and math.isfinite(x) and x > 0]
    return math.exp(statistics.fmean(math.log(x) for x in v)) if v else None


def gain_text(g: float) -> str:
    return f"{g:g}"


def bytes_text(n: int) -> str:
    return f"{n:,} B ({n / 1024:.1f} KiB)"


# ------------------------------------------------------------------------------------------------
# The machine and the header
# ------------------------------------------------------------------------------------------------


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def os_name() -> str:
    try:
        for line in Path("/etc/os-release").read_text().splitlines():
            if line.startswith("PRETTY_NAME="):
                return f"{line.split('=', 1)[1].strip().strip(chr(34))}, {platform.system()} {platform.release()}"
    except OSError:
        pass
    return platform.platform()


def git(*args: str) -> str:
    try:
        return run(["git", *args], cwd=ROOT).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return ""


def versions() -> str:
    parts = [f"Python {platform.python_version()}", f"numpy {np.__version__}"]
    try:
        import sklearn

        parts.append(f"scikit-learn {sklearn.__version__}")
    except ImportError:
        pass
    try:
        import torch

        parts.append(f"torch {torch.__version__}")
    except ImportError:
        pass
    try:
        parts.append(run(["rustc", "--version"]).stdout.split(" (")[0])
    except (OSError, subprocess.CalledProcessError):
        pass
    return ", ".join(parts)


@dataclass
class Context:
    """What every page's header says."""

    command: str
    date: str
    commit: str
    dirty: bool
    cpu: str
    cores: int
    os: str
    versions: str
    load_start: Tuple[float, float, float]


def context(argv: Sequence[str]) -> Context:
    return Context(
        command="python3 benches/report.py " + " ".join(shlex.quote(a) for a in argv),
        date=datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        commit=git("rev-parse", "--short=12", "HEAD") or "unknown",
        dirty=bool(git("status", "--porcelain", "--untracked-files=no")),
        cpu=cpu_model(),
        cores=os.cpu_count() or 1,
        os=os_name(),
        versions=versions(),
        load_start=os.getloadavg(),
    )


def header(title: str, ctx: Context, seconds: float, plan: Plan) -> List[str]:
    load_end = os.getloadavg()
    commit = ctx.commit + (" with uncommitted changes" if ctx.dirty else "")
    other = "--full" if plan.name == "quick" else "--quick"
    return [
        f"# {title}",
        "",
        "<!-- Generated by benches/report.py; edit the script, not this page. -->",
        "",
        f"- Command: `{ctx.command}` ({plan.name} mode; `{other}` "
        + ("runs the whole grid and more repetitions" if plan.name == "quick" else "runs the short version")
        + ")",
        f"- Date: {ctx.date}; commit `{commit}`",
        f"- Machine: {ctx.cpu}, {ctx.cores} cores, {ctx.os}",
        f"- Software: {ctx.versions}; every program on one thread",
        f"- This page took {seconds / 60:.1f} min; load average {ctx.load_start[0]:.2f} at the start, "
        f"{load_end[0]:.2f} at the end",
        "",
    ]


# ------------------------------------------------------------------------------------------------
# Accuracy
# ------------------------------------------------------------------------------------------------


def start_thesis_experiment(hbn: Path, plan: Plan, raw: Path) -> Tuple[subprocess.Popen, Path, List[str]]:
    """Starts ``hbn experiment`` in the background; returns the process, its JSON path and
    its command."""
    out = raw / "thesis_experiment.json"
    cmd = [
        str(hbn), "-q", "experiment",
        "--systems", ",".join(THESIS_SYSTEMS),
        "--gains", ",".join(gain_text(g) for g in plan.thesis_gains),
        "--seeds", ",".join(str(s) for s in plan.thesis_seeds),
        "--json", str(out),
    ]  # fmt: skip
    log = open(raw / "thesis_experiment.log", "w")
    proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT)
    return proc, out, cmd


def thesis_section(rows: Sequence[Mapping[str, Any]], plan: Plan) -> List[str]:
    cells: Dict[Tuple[str, float], List[Mapping[str, Any]]] = {}
    for r in rows:
        cells.setdefault((r["system"], float(r["noise_gain"])), []).append(r)
    seeds = ", ".join(str(s) for s in plan.thesis_seeds)
    spread = (
        f"seed {seeds}" if len(plan.thesis_seeds) == 1 else f"mean +- standard deviation over seeds {seeds}"
    )
    lines = [
        "## The thesis' simulation experiment",
        "",
        "The protocol of the thesis (Sec. 5.1), run by `hbn experiment` with its default training",
        "settings: per simulator, noise gain and seed, one random input of 500 samples is applied",
        "10 times with independent noise; the model is trained on the 10 runs and scored on a",
        "fresh random input of 1000 samples, from `u` and `y` alone. Each cell gives the",
        f"nRMSE ({spread}) of each mode, of open-loop",
        "simulation (the transition GP run from `u` without the sensor) and of the mode the",
        "model chose on held-out data; the last columns are the calibration of that mode's",
        "standard deviation (fraction of the test run within 2 sigma, and the mean normalised",
        "squared error, NEES, which is 1 for a calibrated filter). Table 1 of the thesis is",
        "the gain-1 rows, Table 2 the whole sweep.",
        "",
        "| system | noise gain | runs | EKF | EKF+BLR | UKF | open loop | default mode | EKF+BLR <= EKF (runs) | 2-sigma coverage | mean NEES |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    better_than_open = 0
    factors = []
    blr_wins = 0
    for (system, gain), rs in sorted(cells.items()):
        ekf = [r["nrmse_ekf"] for r in rs]
        blr = [r["nrmse_ekf_blr"] for r in rs]
        modes: Dict[str, int] = {}
        for r in rs:
            modes[str(r["default_mode"])] = modes.get(str(r["default_mode"]), 0) + 1
        chosen = ", ".join(f"{m} x{n}" if len(rs) > 1 else m for m, n in sorted(modes.items()))
        wins = sum(b <= e for b, e in zip(blr, ekf))
        blr_wins += wins
        open_loop = statistics.fmean(r["nrmse_open_loop"] for r in rs)
        if statistics.fmean(ekf) < open_loop:
            better_than_open += 1
        factors.append(open_loop / statistics.fmean(ekf))
        lines.append(
            f"| {system} | {gain_text(gain)} | {len(rs)} | {mean_sd(ekf)} | {mean_sd(blr)} "
            f"| {mean_sd([r['nrmse_ukf'] for r in rs])} | {mean_sd([r['nrmse_open_loop'] for r in rs])} "
            f"| {mean_sd([r['nrmse_default'] for r in rs])} ({chosen}) | {wins}/{len(rs)} "
            f"| {mean_sd([r['calibration_default']['coverage_2sigma'] for r in rs], '.3f')} "
            f"| {mean_sd([r['calibration_default']['mean_nees'] for r in rs], '.2f')} |"
        )
    n_runs = len(rows)
    lines += [
        "",
        f"The EKF's mean nRMSE is below open-loop simulation's in {better_than_open} of {len(cells)} cells "
        f"(open loop / EKF from {min(factors):.1f}x to {max(factors):.1f}x): the measurements correct the "
        f"drift of the learned dynamics. EKF+BLR is at least as accurate as the plain EKF in {blr_wins} of "
        f"{n_runs} runs. No estimate is non-finite"
        + ("." if not any(r.get("non_finite") for r in rows) else " (except in runs flagged `non_finite` in the raw rows)."),
        "",
    ]
    return lines


def grid_methods() -> Tuple[List[str], List[str]]:
    """The grid's methods and the notes about left-out ones."""
    import lstm

    methods = ["hbn", "hbn-ekf", "hbn-ekf-blr", "hbn-open-loop", "sk-gp-ekf", "narx", "floor"]
    notes = []
    if lstm.available():
        methods.insert(5, "lstm")
    else:
        notes.append(
            "The LSTM baseline is left out: torch is not installed in this run "
            "(`pip install torch`, see [baselines.md](baselines.md)); its column is empty."
        )
    return methods, notes


def grid_section(doc: Mapping[str, Any], plan: Plan, notes: Sequence[str]) -> List[str]:
    import run as runner

    rows = runner.summarise(doc["runs"])
    systems = ", ".join(plan.grid_systems)
    gains = ", ".join(gain_text(g) for g in plan.grid_gains)
    seeds = ", ".join(str(s) for s in plan.grid_seeds)

    def nr(row: Mapping[str, Any], name: str) -> Optional[float]:
        m = row["methods"].get(name)
        return None if m is None else m.get("nrmse")

    lines = [
        "## hbn against the baselines and the floor",
        "",
        "What a user gets from hbn's defaults (`hbn train` / `hbn.HysteresisModel.fit` without",
        "options, estimating in the model's default mode) against the estimators a researcher",
        "would otherwise write ([baselines.md](baselines.md)), all trained on the same MCAP logs and",
        "scored by the same code on a test log none of them saw: per simulator, noise gain and seed",
        "`S`, three training logs of 1000 samples with one random input (noise seeds `10 S + 1..3`)",
        "and a test log with another input (`benches/baselines/run.py --grid`). The floor is not an",
        "estimator one could build: the exact posterior of the state given the simulator, `u`, `y`",
        "and the true past states; no causal estimator has a lower expected error. Without noise",
        "(gain 0) the floor is 0: the simulator and the input determine the state.",
        "",
        "- **hbn / best baseline**: hbn's mean nRMSE over the best of the baselines' (below 1:",
        "  hbn is more accurate);",
        "- **excess over the floor**: `(hbn - floor) / (baseline - floor)`, the share of the best",
        "  baseline's error above the floor that hbn still has (0: hbn reaches the floor).",
        "",
        f"Simulators {systems}; noise gains {gains}; "
        + (f"seed {seeds}." if len(plan.grid_seeds) == 1 else f"seeds {seeds}; each cell is the mean over the seeds."),
        "",
        "| system | noise gain | runs | nRMSE hbn | scikit-learn GP-EKF | LSTM | NARX | floor | hbn / best baseline | excess over the floor |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    ratios, excess = [], []
    for r in rows:
        h, base = nr(r, "hbn"), [nr(r, b) for b in runner.BASELINES]
        base = [b for b in base if b is not None]
        best = min(base) if base else None
        fl = nr(r, "floor")
        ratio = h / best if h is not None and best else None
        ex = (h - fl) / (best - fl) if None not in (h, best, fl) and best > fl else None
        if ratio is not None:
            ratios.append(ratio)
        if ex is not None:
            excess.append(ex)
        lines.append(
            f"| {r['system']} | {gain_text(r['gain'])} | {r['runs']} | {fmt(h)} | {fmt(nr(r, 'sk-gp-ekf'))} "
            f"| {fmt(nr(r, 'lstm'))} | {fmt(nr(r, 'narx'))} | {fmt(fl)} | {fmt(ratio, '.2f')} | {fmt(ex, '.2f')} |"
        )
    g = geomean(ratios)
    lines += [""]
    if g is not None:
        lines.append(
            f"Over the {len(ratios)} cells, hbn / best baseline has geometric mean **{g:.2f}**; hbn is "
            f"more accurate in {sum(x < 1 for x in ratios)} of them"
            + (f", and its excess over the floor has median {statistics.median(excess):.2f}." if excess else ".")
        )
        lines.append("")
    lines += list(notes) + ([""] if notes else [])

    lines += [
        "### hbn's modes",
        "",
        "The same fit in each mode, and open-loop simulation from `u` alone; the configuration",
        "is the one training chose on held-out data (kernel, exact GPs or `m` inducing points).",
        "",
        "| system | noise gain | default mode | EKF | EKF+BLR | open loop | chosen configuration (runs) |",
        "|---|---|---|---|---|---|---|",
    ]
    by_cell: Dict[Tuple[str, float], List[Mapping[str, Any]]] = {}
    for run_ in doc["runs"]:
        by_cell.setdefault((run_["system"], float(run_["gain"])), []).append(run_)
    for r in rows:
        configs: Dict[str, int] = {}
        modes: Dict[str, int] = {}
        for run_ in by_cell.get((r["system"], float(r["gain"])), []):
            m = run_["report"]["methods"].get("hbn", {})
            if m.get("config"):
                configs[m["config"]] = configs.get(m["config"], 0) + 1
            if m.get("mode"):
                modes[m["mode"]] = modes.get(m["mode"], 0) + 1
        lines.append(
            f"| {r['system']} | {gain_text(r['gain'])} | {', '.join(f'{k} x{v}' for k, v in sorted(modes.items())) or '-'} "
            f"| {fmt(nr(r, 'hbn-ekf'))} | {fmt(nr(r, 'hbn-ekf-blr'))} | {fmt(nr(r, 'hbn-open-loop'))} "
            f"| {', '.join(f'{k} x{v}' for k, v in sorted(configs.items())) or '-'} |"
        )

    def cal(row: Mapping[str, Any], name: str, key: str, spec: str) -> str:
        m = row["methods"].get(name)
        return fmt(None if m is None else m.get(key), spec)

    lines += [
        "",
        "## Calibration",
        "",
        "How well each estimate's standard deviation describes its error on the test logs of the",
        "grid above: the fraction of samples within 2 standard deviations (0.954 for a Gaussian",
        "error of exactly that size) and the mean NEES (1 when the variance is right; above 1, the",
        "estimate is overconfident). The LSTM and NARX give no standard deviation.",
        "",
        "| system | noise gain | 2-sigma hbn | 2-sigma scikit-learn GP-EKF | 2-sigma floor | NEES hbn | NEES scikit-learn GP-EKF | NEES floor |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['system']} | {gain_text(r['gain'])} | {cal(r, 'hbn', 'coverage_2sigma', '.3f')} "
            f"| {cal(r, 'sk-gp-ekf', 'coverage_2sigma', '.3f')} | {cal(r, 'floor', 'coverage_2sigma', '.3f')} "
            f"| {cal(r, 'hbn', 'mean_nees', '.2f')} | {cal(r, 'sk-gp-ekf', 'mean_nees', '.2f')} "
            f"| {cal(r, 'floor', 'mean_nees', '.2f')} |"
        )
    lines.append("")
    return lines


def accuracy(plan: Plan, raw: Path, hbn: Path, ctx: Context) -> List[str]:
    import run as runner

    t0 = time.perf_counter()
    proc, thesis_json, thesis_cmd = start_thesis_experiment(hbn, plan, raw)
    say(f"thesis experiment started: {' '.join(thesis_cmd[1:])}")
    methods, notes = grid_methods()
    say(f"grid: {len(plan.grid_systems)} simulators x {len(plan.grid_gains)} gains x {len(plan.grid_seeds)} seeds, methods {', '.join(methods)}")
    try:
        with open(raw / "grid.log", "w") as log:
            doc = runner.grid(plan.grid_systems, plan.grid_gains, plan.grid_seeds, raw / "grid", methods=methods, log=log)
    except BaseException:
        proc.kill()
        raise
    say(f"grid done ({len(doc['runs'])} runs, {doc.get('total_seconds', 0):.0f} s); waiting for the thesis experiment")
    if proc.wait() != 0:
        raise RuntimeError(f"hbn experiment failed (exit {proc.returncode}); see {raw / 'thesis_experiment.log'}")
    rows = json.loads(thesis_json.read_text())
    say("thesis experiment done")
    body = [
        "What the tables mean: nRMSE is the RMSE of the estimate of the hidden state `x` divided by",
        "the range of the true `x` on the test run (lower is better; the thesis' measure). Every",
        "run is on simulated data (`hbn simulate`, `crates/hbn-sim`), where the true state is",
        "known. The tables are regenerated by the command above; the performance figures are in",
        "[performance.md](performance.md).",
        "",
    ]
    body += thesis_section(rows, plan)
    body += grid_section(doc, plan, notes)
    return header("Accuracy", ctx, time.perf_counter() - t0, plan) + body


# ------------------------------------------------------------------------------------------------
# Performance
# ------------------------------------------------------------------------------------------------


def simulate(hbn: Path, out: Path, steps: int, input_seed: int, seed: int) -> Path:
    run([hbn, "-q", "simulate", "--system", "bouc-wen", "--steps", str(steps), "--input-seed", str(input_seed),
         "--seed", str(seed), "--noise-gain", "1", "--out", out])  # fmt: skip
    return out


def train(hbn: Path, logs: Sequence[Path], out: Path, extra: Sequence[str] = ()) -> float:
    """``hbn train`` on ``logs``; returns the wall seconds."""
    cmd: List[Any] = [hbn, "-q", "train"]
    for lg in logs:
        cmd += ["--log", lg]
    cmd += [*extra, "--out", out]
    t = time.perf_counter()
    run(cmd)
    return time.perf_counter() - t


def export_sizes(hbn: Path, model: Path, out: Path, precision: str, mode: Optional[str]) -> Dict[str, int]:
    """``hbn export --format c``: the model data and work memory bytes it reports."""
    cmd: List[Any] = [hbn, "export", "--model", model, "--out", out, "--format", "c", "--precision", precision]
    if mode:
        cmd += ["--mode", mode]
    text = run(cmd).stdout
    m = re.search(r"model data (\d+) bytes.*?work memory (\d+) bytes", text)
    if not m:
        raise RuntimeError(f"unexpected output of hbn export:\n{text}")
    files = sum(p.stat().st_size for p in out.iterdir() if p.is_file())
    return {"model_bytes": int(m.group(1)), "work_bytes": int(m.group(2)), "source_bytes": files}


def performance(plan: Plan, raw: Path, hbn: Path, ctx: Context) -> Tuple[List[str], Dict[str, Any]]:
    import common
    import compare_sklearn
    import gp_ekf
    import hbn as hbn_py
    import numpy_filter

    t0 = time.perf_counter()
    wd = raw / "performance"
    wd.mkdir(parents=True, exist_ok=True)
    out: Dict[str, Any] = {}
    # The README's worked example: three bouc-wen training logs with one input, fresh noise.
    train_logs = [simulate(hbn, wd / f"train{i}.mcap", 1000, 1, 10 + i) for i in (1, 2, 3)]
    test_log = simulate(hbn, wd / "test.mcap", plan.step_log, 2, 21)
    models = {
        "default": (wd / "default.hbn", []),
        "exact": (wd / "exact.hbn", ["--inducing", "exact"]),
        "m64": (wd / "m64.hbn", ["--inducing", "64"]),
        "m32": (wd / "m32.hbn", ["--inducing", "32"]),
    }
    seconds = {}
    for name, (path, extra) in models.items():
        say(f"hbn train {' '.join(extra) or '(defaults)'}")
        seconds[name] = train(hbn, train_logs, path, extra)
    out["train_seconds"] = seconds

    # The scikit-learn GP-EKF baseline's fit on the same logs.
    logs = [common.read_log(str(p), common.DEFAULT_PATHS) for p in train_logs]
    t = time.perf_counter()
    gp_ekf.fit(logs, seed=1)
    out["sk_gp_ekf_fit_seconds"] = time.perf_counter() - t

    # Rust step.
    say("step time (Rust)")
    step_cmd = [exe("step_time"), "--model", models["exact"][0], "--model", models["m64"][0], "--log", test_log,
                "--passes", str(plan.step_passes)]  # fmt: skip
    steps = [json.loads(line) for line in run(step_cmd).stdout.splitlines() if line.strip()]
    out["step_time"] = steps

    # Vector step: the simulated finger (2 inputs, 2 state components, 3 sensors).
    say("vector step time (Rust, finger)")
    v_train = wd / "finger-train.mcap"
    v_test = wd / "finger-test.mcap"
    run([hbn, "-q", "simulate", "--system", "finger", "--steps", "3000", "--seed", "1", "--out", v_train])
    run([hbn, "-q", "simulate", "--system", "finger", "--steps", str(plan.step_log), "--seed", "2", "--out", v_test])
    v_models = {"exact": wd / "finger-exact.hbn", "m64": wd / "finger-m64.hbn"}
    for name, path in v_models.items():
        train(hbn, [v_train], path, ["--inducing", "exact" if name == "exact" else "64"])
    v_cmd = [exe("step_time"), "--model", v_models["exact"], "--model", v_models["m64"], "--log", v_test,
             "--passes", str(plan.step_passes)]  # fmt: skip
    v_steps = [json.loads(line) for line in run(v_cmd).stdout.splitlines() if line.strip()]
    out["vector_step_time"] = v_steps

    # numpy EKF and the Python step on the same models and log.
    say("numpy filter and the Python step")
    numpy_rows = {}
    python_rows = []
    for name in ("exact", "m64"):
        path = models[name][0]
        model = hbn_py.HysteresisModel.load(str(path))
        lg = common.read_log(str(test_log), common.DEFAULT_PATHS, rate=model.rate_hz)
        n_np = min(plan.numpy_steps, len(lg))
        doc = numpy_filter.load_model_json(str(path))
        t = time.perf_counter()
        x_np, _ = numpy_filter.numpy_estimate(doc, lg.u[:n_np], lg.y[:n_np])
        numpy_rows[name] = {"us_per_step": 1e6 * (time.perf_counter() - t) / n_np, "steps": n_np}
        for mode in ("ekf", "ekf-blr", "ukf"):
            best = math.inf
            est = None
            for _ in range(max(1, plan.step_passes // 3)):
                t = time.perf_counter()
                est = model.estimate(lg.u, lg.y, mode=mode)
                best = min(best, time.perf_counter() - t)
            diff = float(np.max(np.abs(np.asarray(est.x)[:n_np] - x_np))) if mode == "ekf" else None
            python_rows.append({"model": name, "mode": mode, "us_per_step": 1e6 * best / len(lg), "max_abs_diff": diff})
    out["numpy"] = numpy_rows
    out["python"] = python_rows

    # One GP fit against scikit-learn.
    say(f"GP fit against scikit-learn (n = {', '.join(map(str, plan.fit_sizes))})")
    fits = compare_sklearn.compare(plan.fit_sizes, starts=1, repeats=plan.fit_repeats)
    out["gp_fit"] = fits

    # Firmware.
    say("firmware export")
    firmware = []
    for name, mode in (("default", None), ("m32", "ekf")):
        for precision in ("f64", "f32"):
            d = wd / f"export-{name}-{precision}"
            sizes = export_sizes(hbn, models[name][0], d, precision, mode)
            m = hbn_py.HysteresisModel.load(str(models[name][0]))
            firmware.append({"model": name, "mode": mode or m.default_mode, "precision": precision, **sizes})
    out["firmware"] = firmware
    (raw / "performance.json").write_text(json.dumps(out, indent=1))

    # The page.
    labels = {"exact": "exact GPs (`--inducing exact`)", "m64": "sparse GPs, m = 64 (`--inducing 64`)"}
    body = [
        "What the tables mean: each figure comes with its baseline, measured in the same run on the",
        "same data, and their ratio (above 1: hbn is faster or smaller). The models are trained by",
        "`hbn train` with its defaults, except for the option named, on the README's worked example",
        "(three bouc-wen logs of 1000 samples at 100 Hz with one input and fresh noise); the step is",
        f"timed on a test log of {plan.step_log} samples with another input. Accuracy is in",
        "[accuracy.md](accuracy.md).",
        "",
        "## Estimator step (Rust)",
        "",
        "One step of the filter (prediction, update and the standard deviation) in each mode, over",
        f"whole passes of the test log (`step_time` of `benches/harness`, {plan.step_passes} passes):",
        "the fastest pass is the step's own cost, the median says how much a shared machine took",
        "from it. The baseline is the same EKF written in numpy (`benches/numpy_filter.py`, a",
        "per-sample loop of vectorised numpy, which agrees with hbn's EKF to 1e-6) on the same",
        f"model and log ({plan.numpy_steps} samples). A sample period at 100 Hz is 10,000 us.",
        "",
        "| model | points per GP | mode | hbn step, fastest pass (us) | median pass (us) | numpy EKF step (us) | numpy / hbn | share of a 100 Hz period |",
        "|---|---|---|---|---|---|---|---|",
    ]
    name_of = {str(models[k][0]): k for k in ("exact", "m64")}
    for s in steps:
        k = name_of.get(s["model"], s["model"])
        base = numpy_rows.get(k, {}).get("us_per_step")
        body.append(
            f"| {labels.get(k, k)} | {s['transition_points']} / {s['sensor_points']} | {s['mode']} "
            f"| {s['fastest_us']:.2f} | {s['median_us']:.2f} | {fmt(base, '.0f')} "
            f"| {fmt(base / s['fastest_us'] if base else None, '.0f')}x | {100 * s['fastest_us'] / 10_000:.3f}% |"
        )
    v_name = {str(p): k for k, p in v_models.items()}
    body += [
        "",
        "## Vector step (Rust)",
        "",
        "One step of the vector filter ([vector.md](vector.md)) on the simulated finger (2 inputs,",
        "2 state components, 3 sensors: 5 GPs, an augmented state of 7), trained by `hbn train`",
        f"on 3000 samples, timed like the scalar step on a finger log of {plan.step_log} samples. The",
        "CPU columns count only the time the step's thread ran (Linux schedstat), so they hold on a",
        "busy machine where the wall clock does not.",
        "",
        "| model | mode | fastest pass (us) | median pass (us) | fastest pass, CPU (us) | median pass, CPU (us) |",
        "|---|---|---|---|---|---|",
    ]
    for s in v_steps:
        k = v_name.get(s["model"], s["model"])
        body.append(
            f"| {labels.get(k, k)} | {s['mode']} | {s['fastest_us']:.2f} | {s['median_us']:.2f} "
            f"| {fmt(s.get('fastest_cpu_us'), '.2f')} | {fmt(s.get('median_cpu_us'), '.2f')} |"
        )
    body += [
        "",
        "## Python",
        "",
        "`HysteresisModel.estimate` called from Python on the whole test log (the Rust filter",
        "behind the binding; best of several calls, per sample), against the numpy EKF above.",
        "`max abs(x_numpy - x_hbn)` checks that the two compute the same estimate (EKF only: the",
        "numpy filter implements the EKF).",
        "",
        "| model | mode | hbn from Python (us/step) | numpy EKF (us/step) | numpy / hbn | max abs(x_numpy - x_hbn) |",
        "|---|---|---|---|---|---|",
    ]
    for p in python_rows:
        base = numpy_rows[p["model"]]["us_per_step"]
        body.append(
            f"| {labels[p['model']]} | {p['mode']} | {p['us_per_step']:.2f} | {base:.0f} | {base / p['us_per_step']:.0f}x "
            f"| {fmt(p['max_abs_diff'], '.1e')} |"
        )
    body += [
        "",
        "## Training",
        "",
        "One GP fit: SE-ARD plus noise on `n` points with 4 inputs, one optimiser start, targets",
        "standardised, hbn (`fit_timing` of `benches/harness`) against scikit-learn's",
        "`GaussianProcessRegressor` on the same data (`benches/compare_sklearn.py`). The log",
        "marginal likelihood each reaches (higher is better) shows that the speed is not bought",
        f"with a worse optimum. Median of {plan.fit_repeats} fit(s).",
        "",
        "| n | hbn fit (s) | scikit-learn fit (s) | scikit-learn / hbn | hbn LML | scikit-learn LML |",
        "|---|---|---|---|---|---|",
    ]
    for f in fits:
        body.append(
            f"| {f['n']} | {f['hbn_seconds']:.3f} | {f['sklearn_seconds']:.3f} | {f['speedup']:.1f}x "
            f"| {f['hbn_lml']:.2f} | {f['sklearn_lml']:.2f} |"
        )
    sk = out["sk_gp_ekf_fit_seconds"]
    body += [
        "",
        "Whole models on the worked example's 3000 samples: `hbn train` trains both GPs, chooses",
        "their kernels by evidence and a configuration and mode on held-out data, and tunes the",
        "filter; the scikit-learn GP-EKF baseline fits its two GPs on 600 rows each",
        "([baselines.md](baselines.md)).",
        "",
        "| model | hbn train (s) | scikit-learn GP-EKF fit (s) | scikit-learn / hbn |",
        "|---|---|---|---|",
    ]
    for name, label in (("default", "defaults"), ("exact", "`--inducing exact`"), ("m64", "`--inducing 64`"), ("m32", "`--inducing 32`")):
        body.append(f"| {label} | {seconds[name]:.1f} | {sk:.1f} | {sk / seconds[name]:.2f}x |")
    body += [
        "",
        "## Firmware",
        "",
        "`hbn export --format c` writes the model as constant tables for the C filter of `hbn-ffi`",
        "([firmware.md](firmware.md)): the model data go to flash, the work memory (the step's",
        "scratch, and the f32 reals widened to f64) is RAM the caller provides; the filter's own",
        "state comes on top. The baseline is the same model exported in f64: f32 halves the",
        "reals in flash (the factors the variance is sensitive to stay in two f32 parts), and",
        "the filter widens them to f64 in RAM before it runs.",
        "",
        "| model | mode | precision | model data (flash) | work memory (RAM) | flash f64 / this | RAM f64 / this |",
        "|---|---|---|---|---|---|---|",
    ]
    f64_of = {(f["model"], f["mode"]): f for f in firmware if f["precision"] == "f64"}
    flabels = {"default": "defaults", "m32": "`--inducing 32 --mode ekf`"}
    for f in firmware:
        b = f64_of[(f["model"], f["mode"])]
        body.append(
            f"| {flabels[f['model']]} | {f['mode']} | {f['precision']} | {bytes_text(f['model_bytes'])} "
            f"| {bytes_text(f['work_bytes'])} | {b['model_bytes'] / f['model_bytes']:.3g}x | {b['work_bytes'] / f['work_bytes']:.3g}x |"
        )
    body.append("")
    return header("Performance", ctx, time.perf_counter() - t0, plan) + body, out


# ------------------------------------------------------------------------------------------------
# Main
# ------------------------------------------------------------------------------------------------


def check_raw(path: Path) -> None:
    """Raw runs never go into the repository's tracked tree (git-ignored places are fine)."""
    p = path.resolve()
    try:
        p.relative_to(ROOT)
    except ValueError:
        return
    if subprocess.run(["git", "check-ignore", "-q", str(p)], cwd=ROOT).returncode != 0:
        raise SystemExit(f"--raw {path}: inside the repository; choose a directory outside it (or a git-ignored one)")


def build(no_build: bool) -> Path:
    hbn = Path(os.environ["HBN_BIN"]) if os.environ.get("HBN_BIN") else exe("hbn")
    if not no_build:
        say("cargo build --release -p hbn-cli -p hbn-harness")
        subprocess.run(["cargo", "build", "--release", "-q", "-p", "hbn-cli", "-p", "hbn-harness"], cwd=ROOT, check=True)
    for p in (hbn, exe("step_time"), exe("fit_timing")):
        if not p.is_file():
            raise SystemExit(f"{p} is missing: run without --no-build")
    os.environ["HBN_BIN"] = str(hbn)
    return hbn


def main(argv: Optional[Sequence[str]] = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="See the module docstring (python3 -m pydoc benches/report.py) for what each page holds.")  # fmt: skip
    mode = ap.add_mutually_exclusive_group(required=True)
    mode.add_argument("--quick", action="store_true", help="two simulators, noise gains 0, 1, 10, seed 1 (within 10 minutes)")
    mode.add_argument("--full", action="store_true", help="the whole grid: six simulators, seeds 1-3")
    ap.add_argument("--raw", type=Path, default=None, metavar="DIR", help="keep the raw runs here (outside the repository)")
    ap.add_argument("--only", choices=("accuracy", "performance"), default=None, help="regenerate one page")
    ap.add_argument("--docs", type=Path, default=ROOT / "docs", metavar="DIR", help="where the pages go (default docs/)")
    ap.add_argument("--no-build", action="store_true", help="use the built programs as they are")
    a = ap.parse_args(argv)
    plan = QUICK if a.quick else FULL
    if a.raw is not None:
        check_raw(a.raw)
    try:
        import hbn  # noqa: F401
        import sklearn  # noqa: F401
    except ImportError as e:
        raise SystemExit(f"{e}: install the wheel and scikit-learn (pip install ./hbn-py scikit-learn)")
    ctx = context(argv)
    t0 = time.perf_counter()
    hbn_bin = build(a.no_build)
    with tempfile.TemporaryDirectory(prefix="hbn-report-") as tmp:
        raw = a.raw if a.raw is not None else Path(tmp)
        raw.mkdir(parents=True, exist_ok=True)
        a.docs.mkdir(parents=True, exist_ok=True)
        if a.only in (None, "accuracy"):
            page = accuracy(plan, raw, hbn_bin, ctx)
            (a.docs / "accuracy.md").write_text("\n".join(page))
            say(f"wrote {a.docs / 'accuracy.md'}")
        if a.only in (None, "performance"):
            page, _ = performance(plan, raw, hbn_bin, ctx)
            (a.docs / "performance.md").write_text("\n".join(page))
            say(f"wrote {a.docs / 'performance.md'}")
    say(f"done in {(time.perf_counter() - t0) / 60:.1f} min" + (f"; raw runs in {a.raw}" if a.raw else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
