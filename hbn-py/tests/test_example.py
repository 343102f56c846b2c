"""examples/train_and_plot.py runs and writes a PNG."""

import subprocess
import sys

import pytest


def test_example_writes_png(repo, tmp_path):
    pytest.importorskip("matplotlib")
    out = tmp_path / "example.png"
    r = subprocess.run(
        [sys.executable, str(repo / "examples" / "train_and_plot.py"), str(out)],
        capture_output=True, text=True, timeout=600,
    )
    assert r.returncode == 0, r.stderr
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "nRMSE ekf " in r.stdout and "nRMSE ekf-blr" in r.stdout
