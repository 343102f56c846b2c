#!/usr/bin/env python3
"""hbn against the baselines a researcher would otherwise use, on the SAME MCAP logs.

Methods (see ``docs/baselines.md``):

* ``hbn`` / ``hbn-ekf`` / ``hbn-ekf-blr``: ``hbn.HysteresisModel.fit`` with its defaults on the
  arrays of ``hbn.read_mcap`` (rate from the log; filter-aware training by blocked
  cross-validation over every training log), then ``estimate()`` in the model's default mode (what a user gets), and in
  each mode;
* ``hbn-open-loop``: the same model's GP simulation of ``x`` from ``u`` alone (no sensor, no
  standard deviation): what the filter must beat;
* ``sk-gp-ekf``: scikit-learn SE-ARD GPs on 600 random rows of each training set driving a
  numpy EKF (``gp_ekf.py``);
* ``lstm``: a causal 2-layer LSTM ``(u, y) -> x`` in torch (``lstm.py``; skipped with a notice
  when torch is not installed);
* ``narx``: a NARX network, scikit-learn's ``MLPRegressor`` on standardised windows of the last
  ``W`` samples of ``u`` and ``y`` (``narx.py``; ``W`` and the width chosen on held-out data);
* ``floor`` (simulated logs only: ``--simulate`` and ``--grid``, where it is on by default):
  ``hbn.oracle_estimate``, the exact posterior of the state given ``u`` and ``y`` so far, the true
  past states and the simulator itself. No causal estimator has a lower expected squared error,
  so ``hbn / floor`` says how much any method could still gain.

Every method is trained on the training logs only and scored on the test log by the same
code (``common.score``): RMSE, nRMSE, 1- and 2-sigma coverage, mean NEES, NLPD (``null`` for
the LSTM and NARX, which have no standard deviation), training and estimation seconds.

Usage::

    # your logs (message paths default to those of `hbn simulate`)
    python benches/baselines/run.py --train a.mcap --train b.mcap --test c.mcap \\
        [--u /input.data --x /state.data --y /sensor.data] [--seed 0] [--json out.json]
    # generate the logs with the hbn CLI (thesis protocol of the README's worked example)
    python benches/baselines/run.py --simulate bouc-wen --gain 1 --seed 1 [--steps 1000]
    # systems x gains x seeds: one JSON file and a Markdown table
    python benches/baselines/run.py --grid --systems bouc-wen,maxwell-slip --gains 1,10 \\
        --seeds 1,2 --out-dir grid-out
    # the tables of saved grids, merged
    python benches/baselines/run.py --table grid-out/grid.json other/grid.json

The ``hbn`` CLI is ``$HBN_BIN``, else ``target/release/hbn`` of this repository, else ``hbn``
on the PATH. BLAS, OpenMP and rayon run on one thread unless the environment says otherwise
(frugal on shared machines, and the seconds are comparable).
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "RAYON_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import json
import math
import shutil
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import common  # noqa: E402
import gp_ekf  # noqa: E402
import lstm  # noqa: E402
import narx  # noqa: E402

#: Every method that trains on the logs, in report order (the default of ``--train``/``--test``).
METHODS: Tuple[str, ...] = ("hbn", "hbn-ekf", "hbn-ekf-blr", "hbn-open-loop", "sk-gp-ekf", "lstm", "narx")
#: The floor under causal estimation (``hbn.oracle_estimate``): needs the simulator of the logs.
FLOOR = "floor"
#: Every method, in report order; the default of ``--simulate`` and ``--grid``.
ALL_METHODS: Tuple[str, ...] = METHODS + (FLOOR,)
#: hbn's filter methods: the default mode, then each mode (compared with the baselines).
HBN_METHODS: Tuple[str, ...] = ("hbn", "hbn-ekf", "hbn-ekf-blr")
#: Everything one hbn fit gives: the filter methods and the open-loop GP simulation from ``u``
#: alone (no sensor; the floor a filter must beat, thesis Sec. 5).
HBN_FIT_METHODS: Tuple[str, ...] = HBN_METHODS + ("hbn-open-loop",)
#: The baselines (what hbn is compared with in the ratio).
BASELINES: Tuple[str, ...] = ("sk-gp-ekf", "lstm", "narx")
#: Metric keys of one method's result.
METRICS: Tuple[str, ...] = (
    "rmse",
    "nrmse",
    "coverage_1sigma",
    "coverage_2sigma",
    "mean_nees",
    "nlpd",
    "train_seconds",
    "estimate_seconds",
)
REPO = Path(__file__).resolve().parents[2]


# ------------------------------------------------------------------------------------------------
# Logs
# ------------------------------------------------------------------------------------------------


def hbn_bin() -> str:
    """The ``hbn`` CLI: ``$HBN_BIN``, else this repository's ``target/release/hbn``, else
    ``hbn`` on the PATH. ``FileNotFoundError`` if none exists."""
    env = os.environ.get("HBN_BIN")
    if env:
        if not Path(env).is_file():
            raise FileNotFoundError(f"HBN_BIN={env} is not a file")
        return env
    local = REPO / "target" / "release" / "hbn"
    if local.is_file():
        return str(local)
    found = shutil.which("hbn")
    if found:
        return found
    raise FileNotFoundError("no hbn CLI: set HBN_BIN (e.g. HBN_BIN=target/release/hbn) or build it")


def protocol_seeds(seed: int, n_train: int = 3) -> Dict[str, Any]:
    """Seeds of the simulated logs for run seed ``S`` (thesis protocol, as in the README's
    worked example, which is ``S = 1``): ``n_train`` training logs with input seed ``S`` and
    noise seeds ``10 S + 1 .. 10 S + n_train``; a test log with input seed ``S + 1`` and noise
    seed ``10 S + 11``."""
    return {
        "train": [(seed, 10 * seed + i) for i in range(1, n_train + 1)],
        "test": (seed + 1, 10 * seed + 11),
    }


def simulate_logs(
    system: str, gain: float, seed: int, workdir: Path, steps: int = 1000, n_train: int = 3
) -> Tuple[List[str], str]:
    """Writes the training and test logs of :func:`protocol_seeds` with ``hbn simulate`` into
    ``workdir``; returns ``(training paths, test path)``."""
    exe = hbn_bin()
    workdir.mkdir(parents=True, exist_ok=True)
    seeds = protocol_seeds(seed, n_train)

    def sim(input_seed: int, noise_seed: int, name: str) -> str:
        out = workdir / name
        cmd = [
            exe, "-q", "simulate", "--system", system, "--steps", str(steps),
            "--input-seed", str(input_seed), "--seed", str(noise_seed),
            "--noise-gain", repr(float(gain)), "--out", str(out),
        ]  # fmt: skip
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
        return str(out)

    train = [sim(i, s, f"train{k + 1}.mcap") for k, (i, s) in enumerate(seeds["train"])]
    test = sim(*seeds["test"], "test.mcap")
    return train, test


# ------------------------------------------------------------------------------------------------
# Methods
# ------------------------------------------------------------------------------------------------


def run_hbn(
    train: Sequence[common.Log],
    test: common.Log,
    seed: int,
    paths: Mapping[str, str],
    hbn_params: Optional[Mapping[str, Any]] = None,
) -> Dict[str, Dict[str, Any]]:
    """hbn with its defaults (or with the training parameters ``hbn_params``, keyword arguments
    of ``hbn.HysteresisModel.fit``, e.g. ``{"n_inducing": [None, 64]}`` for model selection):
    one fit (``rate`` from the logs), then the default mode, both
    filter modes and the open-loop simulation. Returns ``{"hbn": {...}, "hbn-ekf": {...},
    "hbn-ekf-blr": {...}, "hbn-open-loop": {...}}`` with ``x``, ``x_std`` (``None`` for the open
    loop), seconds (the training time is the same fit's for all), the guard ``flags`` counts and
    ``model_rate``."""
    import hbn

    t0 = time.perf_counter()
    model = hbn.HysteresisModel.fit(
        [lg.u for lg in train],
        [lg.x for lg in train],
        [lg.y for lg in train],
        rate_hz=train[0].rate,
        seed=seed,
        signals={k: paths[k] for k in ("u", "x", "y")},
        **dict(hbn_params or {}),
    )
    t_fit = time.perf_counter() - t0
    held_out = _held_out(model)
    out: Dict[str, Dict[str, Any]] = {}
    for name, mode in (("hbn", None), ("hbn-ekf", "ekf"), ("hbn-ekf-blr", "ekf-blr")):
        t1 = time.perf_counter()
        est = model.estimate(test.u, test.y, mode=mode)
        out[name] = {
            "mode": mode or model.default_mode,
            "x": np.asarray(est.x),
            "x_std": np.asarray(est.x_std),
            "train_seconds": t_fit,
            "estimate_seconds": time.perf_counter() - t1,
            "flags": est.flag_counts(),
            "model_rate": model.rate_hz,
            "config": _config(model),
            "held_out": held_out,
        }
    t1 = time.perf_counter()
    x_open = np.asarray(model.simulate_open_loop(test.u))
    out["hbn-open-loop"] = {
        "mode": "open-loop",
        "x": x_open,
        "x_std": None,
        "train_seconds": t_fit,
        "estimate_seconds": time.perf_counter() - t1,
        "model_rate": model.rate_hz,
    }
    return out


def _config(model: Any) -> str:
    """The trained configuration (the chosen one under model selection), e.g. ``"matern52
    exact"``, ``"se-ard m=64"``, ``"matern52 m=64 lags=1"`` or ``"matern52 exact
    sensor=memory"`` (as ``hbn train`` names candidates)."""
    p = model.params
    m = None if p["n_inducing"] == "exact" else p["n_inducing"]
    return _name(p["transition_kernel"], p["sensor_kernel"], m, p.get("lags") or [], p.get("sensor_inputs", "thesis"))


def _name(transition: str, sensor: str, m: Optional[int], lags: Sequence[float], sensor_inputs: str = "thesis") -> str:
    """A configuration named as ``hbn train`` names candidates: the kernel (both, comma-separated,
    when they differ), ``exact`` or ``m=M``, then any lags, then a sensor other than the
    thesis' (``sensor=memory``)."""
    kernels = transition if transition == sensor else f"{transition},{sensor}"
    tail = f" lags={','.join(f'{t:g}' for t in lags)}" if lags else ""
    if sensor_inputs != "thesis":
        tail += f" sensor={sensor_inputs}"
    return f"{kernels} {'exact' if m is None else f'm={m}'}{tail}"


def _held_out(model: Any) -> Optional[Dict[str, Any]]:
    """The held-out scores training chose by (``None`` without validation): the default mode's
    held-out nRMSE and NLPD, and under model selection every candidate's default mode with its
    scores (``config`` named as ``hbn train`` names it, ``chosen``). Recorded so that a
    selection rule can be studied on a grid's runs without training again."""
    v = (model.summary or {}).get("validation")
    if not v:
        return None
    mode = v.get("default_mode")
    row = next((r for r in v.get("rows", []) if r.get("mode") == mode), None)

    def scores(s: Mapping[str, Any]) -> Dict[str, Any]:
        cal = s.get("calibration", {})
        return {"nrmse": s.get("nrmse"), "nlpd": cal.get("nlpd"), "coverage_2sigma": cal.get("coverage_2sigma")}

    candidates = []
    for c in v.get("candidates", []):
        cand = c.get("candidate", {})
        scored = c.get("scored")
        name = _name(
            _kernel_name(cand.get("transition_kernel", {})),
            _kernel_name(cand.get("sensor_kernel", {})),
            cand.get("n_inducing"),
            cand.get("lags") or [],
            cand.get("sensor_inputs", "thesis"),
        )
        candidates.append({
            "config": name,
            "chosen": bool(c.get("chosen")),
            "lost": c.get("lost", 0),
            "mode": scored[0] if scored else None,
            **(scores(scored[1]) if scored else {"nrmse": None, "nlpd": None, "coverage_2sigma": None}),
        })  # fmt: skip
    return {"mode": mode, **(scores(row["tuned"]) if row else {}), "candidates": candidates}


def _kernel_name(k: Mapping[str, Any]) -> str:
    """A kernel of a model file's candidate table (``{"family": "se-ard", "direction": false}``)
    by its ``hbn train`` name (``se-ard``; the warped family with the direction factor is
    ``thesis``)."""
    family = str(k.get("family"))
    if k.get("direction"):
        return "thesis" if family == "warped" else f"{family} with the direction factor"
    return family


def _finite_or_none(v: Any) -> Any:
    """JSON-safe: NaN/Inf floats become None (JSON has no NaN)."""
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def evaluate(
    train_paths: Sequence[str],
    test_path: str,
    paths: Mapping[str, str] = common.DEFAULT_PATHS,
    seed: int = 0,
    methods: Sequence[str] = METHODS,
    gp_rows: int = gp_ekf.GP_ROWS,
    lstm_config: Optional[lstm.LstmConfig] = None,
    narx_config: Optional[narx.NarxConfig] = None,
    log: Any = None,
    hbn_params: Optional[Mapping[str, Any]] = None,
    simulated: Optional[Tuple[str, float]] = None,
) -> Dict[str, Any]:
    """Trains every method in ``methods`` on ``train_paths`` and scores it on ``test_path``
    (hbn with the training parameters ``hbn_params``, see :func:`run_hbn`). ``simulated``: the
    ``(system, noise gain)`` of simulated logs, which the method ``floor`` needs.

    Returns ``{"rate", "train_logs", "test_log", "seed", "n_train", "n_test", "notices",
    "methods": {name: {metrics..., "samples", extra}}}``; a method that fails gets
    ``{"error": message}`` instead of metrics (and a notice), a skipped LSTM is absent from
    ``methods`` and its reason is in ``notices``.
    """
    unknown = set(methods) - set(ALL_METHODS)
    if unknown:
        raise ValueError(f"unknown methods {sorted(unknown)}; choose from {', '.join(ALL_METHODS)}")
    if FLOOR in methods and simulated is None:
        raise ValueError("the method `floor` needs simulated logs (--simulate or --grid): it runs the simulator")
    train, test = common.read_logs(train_paths, test_path, paths)
    report: Dict[str, Any] = {
        "rate": train[0].rate,
        "train_logs": [str(p) for p in train_paths],
        "test_log": str(test_path),
        "paths": dict(paths),
        "seed": seed,
        "n_train": [len(lg) for lg in train],
        "n_test": len(test),
        "notices": [],
        "methods": {},
    }
    raw: Dict[str, Dict[str, Any]] = {}

    def note(msg: str) -> None:
        report["notices"].append(msg)
        print(msg, file=log or sys.stderr)

    if any(m in HBN_FIT_METHODS for m in methods):
        try:
            raw.update({k: v for k, v in run_hbn(train, test, seed, paths, hbn_params).items() if k in methods})
        except Exception as e:  # a failing method must not hide the others' figures
            for m in methods:
                if m in HBN_FIT_METHODS:
                    raw[m] = {"error": f"{type(e).__name__}: {e}"}
            note(f"hbn failed: {e}")
    if "sk-gp-ekf" in methods:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # sklearn's ConvergenceWarning about bounds
                raw["sk-gp-ekf"] = gp_ekf.run(train, test, seed=seed, rows=gp_rows)
        except Exception as e:
            raw["sk-gp-ekf"] = {"error": f"{type(e).__name__}: {e}"}
            note(f"sk-gp-ekf failed: {e}")
    if "lstm" in methods:
        if not lstm.available():
            note(lstm.SKIP_NOTICE)
        else:
            try:
                raw["lstm"] = lstm.run(train, test, seed=seed, config=lstm_config)
            except Exception as e:
                raw["lstm"] = {"error": f"{type(e).__name__}: {e}"}
                note(f"lstm failed: {e}")
    if "narx" in methods:
        try:
            raw["narx"] = narx.run(train, test, seed=seed, config=narx_config)
        except Exception as e:
            raw["narx"] = {"error": f"{type(e).__name__}: {e}"}
            note(f"narx failed: {e}")
    if FLOOR in methods and simulated is not None:
        try:
            raw[FLOOR] = run_floor(test, *simulated)
        except NoFloor as e:
            note(f"floor skipped: {e}")
        except Exception as e:
            raw[FLOOR] = {"error": f"{type(e).__name__}: {e}"}
            note(f"floor failed: {e}")
    for name in ALL_METHODS:
        if name not in raw:
            continue
        r = raw[name]
        if "error" in r:
            report["methods"][name] = {"error": r["error"]}
            continue
        scores = common.score(r["x"], r["x_std"], test.x)
        scores["train_seconds"] = r["train_seconds"]
        scores["estimate_seconds"] = r["estimate_seconds"]
        extra = {k: v for k, v in r.items() if k not in ("x", "x_std", "train_seconds", "estimate_seconds")}
        report["methods"][name] = {k: _finite_or_none(v) for k, v in {**scores, **extra}.items()}
    return report


class NoFloor(Exception):
    """A simulator with no exact floor (its disturbance propagates through its dynamics, as
    ``soft-actuator-load``'s): the floor is skipped with a notice."""


def run_floor(test: common.Log, system: str, gain: float) -> Dict[str, Any]:
    """The floor under causal estimation on the simulated test log (``hbn.oracle_estimate``;
    nothing is trained). :class:`NoFloor` for a simulator that has none."""
    import hbn

    t0 = time.perf_counter()
    try:
        o = hbn.oracle_estimate(system, test.u, test.x, test.y, noise_gain=gain, rate_hz=test.rate)
    except hbn.ConfigError as e:
        # A known system refused on `system`: its disturbance propagates, no exact floor.
        if getattr(e, "keyword", None) == "system" and system in hbn.SYSTEMS:
            raise NoFloor(str(e)) from e
        raise
    return {"x": o["mean"], "x_std": o["std"], "train_seconds": 0.0, "estimate_seconds": time.perf_counter() - t0}


def _forget_tmp(report: Dict[str, Any]) -> None:
    """Replaces the log paths of a report by their file names (for logs in a deleted
    temporary directory)."""
    report["train_logs"] = [Path(p).name for p in report["train_logs"]]
    report["test_log"] = Path(report["test_log"]).name


def format_report(report: Mapping[str, Any]) -> str:
    """A plain-text table of one :func:`evaluate` report."""
    head = f"{'method':<12} {'RMSE':>9} {'nRMSE':>8} {'cov1s':>6} {'cov2s':>6} {'NEES':>8} {'NLPD':>8} {'train s':>8} {'est s':>7}"
    lines = [f"test {report['test_log']} ({report['n_test']} samples at {report['rate']:g} Hz), seed {report['seed']}", head]

    def f(v: Any, fmt: str) -> str:
        width = int(fmt.split(".")[0]) if fmt[0].isdigit() else 0
        return "-".rjust(width) if v is None else format(v, fmt)

    for name, m in report["methods"].items():
        if "error" in m:
            lines.append(f"{name:<12} error: {m['error']}")
            continue
        lines.append(
            f"{name:<12} {f(m['rmse'], '9.5f')} {f(m['nrmse'], '8.4f')} {f(m['coverage_1sigma'], '6.3f')} "
            f"{f(m['coverage_2sigma'], '6.3f')} {f(m['mean_nees'], '8.3g')} {f(m['nlpd'], '8.3f')} "
            f"{m['train_seconds']:8.2f} {m['estimate_seconds']:7.3f}"
        )
    for n in report["notices"]:
        lines.append(f"note: {n}")
    return "\n".join(lines)


# ------------------------------------------------------------------------------------------------
# Grid
# ------------------------------------------------------------------------------------------------


def _mean(vals: Sequence[Optional[float]]) -> Optional[float]:
    """Mean of the non-None values (None if there are none)."""
    v = [x for x in vals if x is not None]
    return float(np.mean(v)) if v else None


def summarise(runs: Sequence[Mapping[str, Any]]) -> List[Dict[str, Any]]:
    """Per (system, gain): the number of runs, and per method the mean and standard deviation
    of nRMSE and the mean coverages and NEES over the runs; plus ``ratio_<hbn mode>`` = mean
    nRMSE of that hbn mode / the best (lowest) mean nRMSE among the baselines present, and
    ``floor_ratio_hbn`` = hbn's (default mode) / the floor's."""
    cells: Dict[Tuple[str, float], List[Mapping[str, Any]]] = {}
    for r in runs:
        cells.setdefault((r["system"], float(r["gain"])), []).append(r)
    rows = []
    for (system, gain), rs in sorted(cells.items()):
        row: Dict[str, Any] = {"system": system, "gain": gain, "runs": len(rs), "methods": {}}
        for name in ALL_METHODS:
            ms = [r["report"]["methods"].get(name) for r in rs]
            ms = [m for m in ms if m is not None and "error" not in m]
            if not ms:
                continue
            nr = [m["nrmse"] for m in ms if m["nrmse"] is not None]
            row["methods"][name] = {
                "runs": len(ms),
                "nrmse": _mean(nr),
                "nrmse_sd": float(np.std(nr)) if nr else None,
                "coverage_1sigma": _mean([m["coverage_1sigma"] for m in ms]),
                "coverage_2sigma": _mean([m["coverage_2sigma"] for m in ms]),
                "mean_nees": _mean([m["mean_nees"] for m in ms]),
                "train_seconds": _mean([m["train_seconds"] for m in ms]),
            }
        base = [row["methods"][b]["nrmse"] for b in BASELINES if b in row["methods"] and row["methods"][b]["nrmse"] is not None]
        best = min(base) if base else None
        for h in HBN_METHODS:
            hm = row["methods"].get(h)
            ok = hm is not None and hm["nrmse"] is not None and best is not None and best > 0
            row[f"ratio_{h}"] = hm["nrmse"] / best if ok else None
        hm, fl = row["methods"].get("hbn"), row["methods"].get(FLOOR)
        ok = hm is not None and fl is not None and hm["nrmse"] is not None and fl["nrmse"] is not None and fl["nrmse"] > 0
        row["floor_ratio_hbn"] = hm["nrmse"] / fl["nrmse"] if ok else None
        rows.append(row)
    return rows


def markdown_tables(rows: Sequence[Mapping[str, Any]]) -> str:
    """Two Markdown tables of :func:`summarise`'s rows: mean nRMSE per method (with the
    hbn/best-baseline ratios), and the calibration of the methods that give a std."""

    def cell(m: Optional[Mapping[str, Any]], key: str, fmt: str) -> str:
        if m is None or m.get(key) is None:
            return "-"
        return format(m[key], fmt)

    out = [
        "| system | gain | runs | nRMSE hbn (default mode) | nRMSE hbn EKF | nRMSE hbn EKF+BLR | nRMSE hbn open loop | nRMSE sklearn GP-EKF | nRMSE LSTM | nRMSE NARX | hbn / best baseline | hbn EKF / best baseline | hbn EKF+BLR / best baseline | nRMSE floor | hbn / floor |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        ms = r["methods"]
        nr = []
        for name in METHODS:
            m = ms.get(name)
            if m is None or m["nrmse"] is None:
                nr.append("-")
            else:
                nr.append(f"{m['nrmse']:.4f} +- {m['nrmse_sd']:.4f}")
        out.append(
            f"| {r['system']} | {r['gain']:g} | {r['runs']} | " + " | ".join(nr)
            + f" | {cell(r, 'ratio_hbn', '.2f')} | {cell(r, 'ratio_hbn-ekf', '.2f')}"
            + f" | {cell(r, 'ratio_hbn-ekf-blr', '.2f')}"
            + f" | {cell(ms.get(FLOOR), 'nrmse', '.4f')} | {cell(r, 'floor_ratio_hbn', '.2f')} |"
        )
    out += [
        "",
        "| system | gain | 1-sigma / 2-sigma coverage, mean NEES: hbn (default mode) | hbn EKF | hbn EKF+BLR | sklearn GP-EKF |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        cols = []
        for name in ("hbn", "hbn-ekf", "hbn-ekf-blr", "sk-gp-ekf"):
            m = r["methods"].get(name)
            cols.append(
                f"{cell(m, 'coverage_1sigma', '.3f')} / {cell(m, 'coverage_2sigma', '.3f')}, {cell(m, 'mean_nees', '.3g')}"
            )
        out.append(f"| {r['system']} | {r['gain']:g} | " + " | ".join(cols) + " |")
    return "\n".join(out) + "\n"


def grid(
    systems: Sequence[str],
    gains: Sequence[float],
    seeds: Sequence[int],
    out_dir: Path,
    steps: int = 1000,
    methods: Sequence[str] = ALL_METHODS,
    gp_rows: int = gp_ekf.GP_ROWS,
    lstm_config: Optional[lstm.LstmConfig] = None,
    narx_config: Optional[narx.NarxConfig] = None,
    keep_logs: bool = False,
    log: Any = None,
    hbn_params: Optional[Mapping[str, Any]] = None,
) -> Dict[str, Any]:
    """Runs :func:`evaluate` on simulated logs for every system x gain x seed, writing
    ``out_dir/grid.json`` (after every run, so a long grid can be stopped and read) and
    ``out_dir/grid.md``. Returns the JSON content."""
    out_dir.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    doc: Dict[str, Any] = {
        "systems": list(systems),
        "gains": [float(g) for g in gains],
        "seeds": [int(s) for s in seeds],
        "steps": steps,
        "methods": list(methods),
        "gp_rows": gp_rows,
        "hbn_params": dict(hbn_params or {}),
        "runs": [],
    }
    for system in systems:
        for gain in gains:
            for seed in seeds:
                t0 = time.perf_counter()
                with tempfile.TemporaryDirectory(prefix="hbn-baselines-") as tmp:
                    wd = out_dir / "logs" / f"{system}-g{gain:g}-s{seed}" if keep_logs else Path(tmp)
                    train, test = simulate_logs(system, gain, seed, wd, steps=steps)
                    rep = evaluate(train, test, seed=seed, methods=methods, gp_rows=gp_rows, lstm_config=lstm_config, narx_config=narx_config, log=log, hbn_params=hbn_params, simulated=(system, float(gain)))
                if not keep_logs:
                    _forget_tmp(rep)
                doc["runs"].append({"system": system, "gain": float(gain), "seed": seed, "report": rep})
                print(f"[{system} gain {gain:g} seed {seed}: {time.perf_counter() - t0:.1f} s]", file=log or sys.stderr)
                print(format_report(rep), file=log or sys.stderr)
                doc["summary"] = summarise(doc["runs"])
                doc["total_seconds"] = time.perf_counter() - t_start
                (out_dir / "grid.json").write_text(json.dumps(doc, indent=1))
    (out_dir / "grid.md").write_text(markdown_tables(doc.get("summary", [])))
    return doc


# ------------------------------------------------------------------------------------------------
# CLI
# ------------------------------------------------------------------------------------------------


def _csv(s: str, kind: type) -> List[Any]:
    """``"a,b"`` -> ``[kind(a), kind(b)]``."""
    return [kind(x) for x in s.split(",") if x.strip()]


def main(argv: Optional[Sequence[str]] = None) -> int:
    """The command line (see the module docstring); returns the exit code."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    src = ap.add_argument_group("data (one of)")
    src.add_argument("--train", action="append", default=[], metavar="LOG", help="training MCAP log (repeat)")
    src.add_argument("--test", metavar="LOG", help="test MCAP log (needs the state x, for scoring)")
    src.add_argument("--simulate", metavar="SYSTEM", help="generate the logs with `hbn simulate` (thesis protocol)")
    src.add_argument("--grid", action="store_true", help="loop --systems x --gains x --seeds")
    src.add_argument("--table", nargs="+", type=Path, metavar="GRID_JSON", help="print the Markdown tables of saved grid.json files (merged)")
    ap.add_argument("--u", default=common.DEFAULT_PATHS["u"], help="message path of the input u")
    ap.add_argument("--x", default=common.DEFAULT_PATHS["x"], help="message path of the state x")
    ap.add_argument("--y", default=common.DEFAULT_PATHS["y"], help="message path of the sensor output y")
    ap.add_argument("--seed", type=int, default=None, help="seed of every method (and of the simulated logs); default 0 (1 with --simulate)")
    ap.add_argument("--gain", type=float, default=1.0, help="noise gain for --simulate")
    ap.add_argument("--steps", type=int, default=1000, help="samples per simulated log")
    ap.add_argument("--systems", default="bouc-wen,maxwell-slip", help="--grid systems")
    ap.add_argument("--gains", default="1,10", help="--grid noise gains")
    ap.add_argument("--seeds", default="1,2", help="--grid seeds")
    ap.add_argument("--methods", default=None,
                    help=f"subset of {','.join(ALL_METHODS)}; default all (without {FLOOR} for --train/--test logs)")  # fmt: skip
    ap.add_argument("--no-lstm", action="store_true", help="leave the LSTM out")
    ap.add_argument("--gp-rows", type=int, default=gp_ekf.GP_ROWS, help="rows per scikit-learn GP")
    ap.add_argument("--lstm-steps", type=int, default=lstm.LstmConfig().max_steps, help="most LSTM updates")
    ap.add_argument("--workdir", type=Path, default=None, help="keep simulated logs here (default: a temporary directory)")
    ap.add_argument("--json", type=Path, default=None, help="write the report as JSON")
    ap.add_argument("--out-dir", type=Path, default=Path("baselines-grid"), help="--grid output directory")
    ap.add_argument("--hbn-params", type=json.loads, default={}, metavar="JSON",
                    help='hbn training parameters, keyword arguments of hbn.HysteresisModel.fit, e.g. \'{"n_inducing": [null, 64]}\'')  # fmt: skip
    a = ap.parse_args(argv)
    if not isinstance(a.hbn_params, dict):
        ap.error("--hbn-params must be a JSON object")

    default_methods = METHODS if (a.train or a.test) else ALL_METHODS
    chosen = default_methods if a.methods is None else _csv(a.methods, str)
    methods = [m for m in chosen if not (a.no_lstm and m == "lstm")]
    paths = {"u": a.u, "x": a.x, "y": a.y}
    cfg = lstm.LstmConfig(max_steps=a.lstm_steps)
    modes = sum([bool(a.train or a.test), a.simulate is not None, a.grid, a.table is not None])
    if modes != 1:
        ap.error("give exactly one of: --train ... --test LOG, --simulate SYSTEM, --grid, --table")
    if a.table is not None:
        runs = [r for p in a.table for r in json.loads(p.read_text())["runs"]]
        print(markdown_tables(summarise(runs)), end="")
        return 0
    if a.grid:
        t0 = time.perf_counter()
        doc = grid(_csv(a.systems, str), _csv(a.gains, float), _csv(a.seeds, int), a.out_dir, steps=a.steps,
                   methods=methods, gp_rows=a.gp_rows, lstm_config=cfg, keep_logs=a.workdir is not None, hbn_params=a.hbn_params)  # fmt: skip
        print(markdown_tables(doc.get("summary", [])))
        print(f"grid: {len(doc['runs'])} runs in {time.perf_counter() - t0:.0f} s; wrote {a.out_dir / 'grid.json'} and {a.out_dir / 'grid.md'}")
        return 0
    if a.simulate is not None:
        seed = 1 if a.seed is None else a.seed
        with tempfile.TemporaryDirectory(prefix="hbn-baselines-") as tmp:
            wd = a.workdir if a.workdir is not None else Path(tmp)
            train, test = simulate_logs(a.simulate, a.gain, seed, wd, steps=a.steps)
            rep = evaluate(train, test, paths, seed=seed, methods=methods, gp_rows=a.gp_rows, lstm_config=cfg, hbn_params=a.hbn_params,
                           simulated=(a.simulate, a.gain))  # fmt: skip
        if a.workdir is None:  # the temporary directory is gone: keep the file names only
            _forget_tmp(rep)
        rep.update({"system": a.simulate, "gain": a.gain, "protocol": protocol_seeds(seed)})
    else:
        if not a.train or not a.test:
            ap.error("--train needs --test, and --test needs at least one --train")
        seed = 0 if a.seed is None else a.seed
        rep = evaluate(a.train, a.test, paths, seed=seed, methods=methods, gp_rows=a.gp_rows, lstm_config=cfg, hbn_params=a.hbn_params)
    print(format_report(rep))
    if a.json is not None:
        a.json.write_text(json.dumps(rep, indent=1))
        print(f"wrote {a.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
