"""Model files and logs shared with the `hbn` CLI, both ways.

The CLI is found from $HBN_BIN, else <repo>/target/release/hbn, else <repo>/target/debug/hbn;
without one the tests skip. The CLI interface assumed here (adjust CLI_* below if it changes):

    hbn simulate --system SYS --steps N --seed S --noise-gain G --out LOG.mcap
    hbn train --log LOG.mcap --out MODEL.hbn [--max-points N]
    hbn inspect MODEL.hbn
    hbn estimate --model MODEL.hbn --log LOG.mcap --csv OUT.csv

The estimate CSV has a header row (`t,x,x_std,...`); the estimate column is x (or x_hat / x_est).
Python reads u and y (in that order, like `hbn estimate`) with read_mcap at the model's rate, so
both run the filter on the same resampled samples.
"""

import csv
import re
import subprocess

import numpy as np
import pytest

import hbn
from conftest import find_hbn_bin

CLI_SIMULATE = ["simulate", "--system", "{system}", "--steps", "{steps}", "--seed", "{seed}",
                "--noise-gain", "1", "--out", "{out}"]
CLI_TRAIN = ["train", "--log", "{log}", "--out", "{out}", "--max-points", "{max_points}"]
CLI_INSPECT = ["inspect", "{model}"]
CLI_ESTIMATE = ["estimate", "--model", "{model}", "--log", "{log}", "--csv", "{out}"]
X_COLUMNS = ("x", "x_hat", "x_est", "x_estimate")


@pytest.fixture(scope="module")
def cli():
    exe = find_hbn_bin()
    if exe is None:
        pytest.skip("no hbn CLI binary: set HBN_BIN or build target/release/hbn (cargo build --release -p hbn-cli)")
    try:
        help_text = subprocess.run([exe, "--help"], capture_output=True, text=True, timeout=60).stdout
    except OSError as e:
        pytest.skip(f"cannot run {exe}: {e}")
    if "estimate" not in help_text or "train" not in help_text:
        pytest.skip(f"{exe} has no train/estimate subcommands yet")

    def run(template, **kw):
        args = [exe] + [a.format(**kw) for a in template]
        r = subprocess.run(args, capture_output=True, text=True, timeout=900)
        assert r.returncode == 0, f"{' '.join(args)} failed ({r.returncode}):\n{r.stdout}\n{r.stderr}"
        return r.stdout

    return run


def _signal_paths(log, model=None):
    """Message paths of u, x, y: from the model's signals if it has them, else from the topics."""
    if model is not None:
        s = model.signals
        paths = {k: s[role]["path"] for k, role in (("u", "input"), ("x", "state"), ("y", "output"))}
        if all(paths.values()):
            return paths
    topics = [t["topic"] for t in hbn.list_topics(log)]
    pats = {"u": r"(^|/)(u|input|pressure)$", "x": r"(^|/)(x|state|angle)$", "y": r"(^|/)(y|output|sensor)$"}
    out = {}
    for k, pat in pats.items():
        hit = [t for t in topics if re.search(pat, t)]
        assert len(hit) == 1, f"cannot tell the {k} topic among {topics}"
        out[k] = hit[0] + ".data"
    return out


def _csv_x(path):
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    header = [h.strip() for h in rows[0]]
    col = next((header.index(c) for c in X_COLUMNS if c in header), None)
    assert col is not None, f"no estimate column among {header}"
    return np.array([float(r[col]) for r in rows[1:] if r])


@pytest.fixture(scope="module")
def logs(cli, tmp_path_factory):
    d = tmp_path_factory.mktemp("cli")
    train, test = d / "train.mcap", d / "test.mcap"
    cli(CLI_SIMULATE, system="duhem", steps=700, seed=1, out=train)
    cli(CLI_SIMULATE, system="duhem", steps=400, seed=2, out=test)
    return d, train, test


def test_cli_trained_model_loads_and_matches_cli_estimate(cli, logs):
    d, train, test = logs
    model_path, out_csv = d / "cli.hbn", d / "cli_est.csv"
    cli(CLI_TRAIN, log=train, out=model_path, max_points=200)
    model = hbn.HysteresisModel.load(model_path)
    paths = _signal_paths(test, model)
    truth = hbn.read_mcap(test, {"u": paths["u"], "x": paths["x"], "y": paths["y"]}, rate_hz=model.rate_hz)
    e = model.estimate(truth["u"], truth["y"])
    ol = model.simulate_open_loop(truth["u"])
    rmse = lambda a: float(np.sqrt(np.mean((a - truth["x"]) ** 2)))  # noqa: E731
    assert rmse(e.x) < rmse(ol)
    data = hbn.read_mcap(test, {"u": paths["u"], "y": paths["y"]}, rate_hz=model.rate_hz)
    est = model.estimate(data["u"], data["y"])
    cli(CLI_ESTIMATE, model=model_path, log=test, out=out_csv)
    x_cli = _csv_x(out_csv)
    assert x_cli.shape == est.x.shape
    np.testing.assert_allclose(est.x, x_cli, rtol=0, atol=1e-12)


def test_python_trained_model_is_read_by_cli(cli, logs):
    d, train, test = logs
    paths = _signal_paths(train)
    data = hbn.read_mcap(train, paths, rate_hz=100.0)
    model = hbn.HysteresisModel.fit(
        data["u"], data["x"], data["y"], rate_hz=100.0, max_points=200, n_starts=1, signals=paths
    )
    model_path, out_csv = d / "py.hbn", d / "py_est.csv"
    model.save(model_path)
    text = cli(CLI_INSPECT, model=model_path)
    assert text.strip(), "hbn inspect printed nothing"
    cli(CLI_ESTIMATE, model=model_path, log=test, out=out_csv)
    te = hbn.read_mcap(test, {"u": paths["u"], "y": paths["y"]}, rate_hz=model.rate_hz)
    est = model.estimate(te["u"], te["y"])
    np.testing.assert_allclose(est.x, _csv_x(out_csv), rtol=0, atol=1e-12)
