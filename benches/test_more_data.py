"""End-to-end test of ``benches/more_data.py`` on a tiny grid (one system, gain 1, one seed,
two short sizes): a row per cell with a finite score per size and test log, the candidate and
mode training chose, and the summary lines.

    pytest benches/test_more_data.py
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parent / "more_data.py"


def test_a_tiny_grid_prints_a_row_and_the_summary() -> None:
    r = subprocess.run(
        [sys.executable, str(SCRIPT), "--systems", "duhem", "--gains", "1", "--seeds", "1",
         "--sizes", "300,600", "--tests", "2", "--test-steps", "300",
         "--fit", '{"max_points": 80, "n_starts": 1}'],
        capture_output=True, text=True, timeout=900,
    )
    assert r.returncode == 0, r.stderr
    rows = [json.loads(l) for l in r.stdout.splitlines() if l.startswith("{")]
    assert len(rows) == 1
    row = rows[0]
    assert sorted(row["sizes"]) == ["300", "600"], row
    for size in row["sizes"].values():
        assert len(size["tests"]) == 2 and all(math.isfinite(v) and v > 0 for v in size["tests"])
        assert size["chosen"] and size["mode"] in ("ekf", "ekf-blr", "ukf"), size
    assert math.isclose(row["ratio"], row["sizes"]["600"]["nrmse"] / row["sizes"]["300"]["nrmse"])
    assert "gain 1: 600 / 300 samples" in r.stdout and "all: mean ratio" in r.stdout


def test_one_size_is_refused() -> None:
    r = subprocess.run(
        [sys.executable, str(SCRIPT), "--sizes", "1000"], capture_output=True, text=True,
        timeout=60,
    )
    assert r.returncode != 0 and "--sizes" in r.stderr
