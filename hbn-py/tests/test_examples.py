"""The user examples in examples/ run as documented (small sizes, in a temporary directory)."""

import subprocess
import sys

import pytest


def run(repo, cwd, script, *args):
    r = subprocess.run(
        [sys.executable, str(repo / "examples" / script), *map(str, args)],
        capture_output=True, text=True, timeout=600, cwd=cwd,
    )
    assert r.returncode == 0, r.stderr
    return r.stdout


def test_train_and_plot_writes_a_png(repo, tmp_path):
    pytest.importorskip("matplotlib")
    out = run(
        repo, tmp_path, "train_and_plot.py",
        "--out", "example.png", "--train-samples", 600, "--test-samples", 300,
    )
    assert (tmp_path / "example.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "nRMSE ekf " in out and "nRMSE ekf-blr" in out and "nRMSE open-loop" in out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["example.png"]


def test_explore_in_the_loop_keeps_the_bounds(repo, tmp_path):
    out = run(
        repo, tmp_path, "explore_in_the_loop.py",
        "--system", "duhem", "--samples", 400, "--test-samples", 500,
    )
    assert "bounds kept: True; increment bound kept: True" in out
    assert "nRMSE explorer" in out and "nRMSE random ramps" in out
    assert list(tmp_path.iterdir()) == []
