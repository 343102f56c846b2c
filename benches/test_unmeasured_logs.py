"""End-to-end test of ``benches/unmeasured_logs.py`` on a tiny grid (one system, gain 1, one
seed, short logs): a row with three finite scores, EM's rounds recorded, and the summary.

    pytest benches/test_unmeasured_logs.py
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parent / "unmeasured_logs.py"


def test_a_tiny_grid_prints_a_row_and_the_summary() -> None:
    r = subprocess.run(
        [sys.executable, str(SCRIPT), "--systems", "duhem", "--gains", "1", "--seeds", "1",
         "--steps", "300", "--test-steps", "300", "--extra", "1"],
        capture_output=True, text=True, timeout=900,
    )
    assert r.returncode == 0, r.stderr
    rows = [json.loads(l) for l in r.stdout.splitlines() if l.startswith("{")]
    assert len(rows) == 1
    row = rows[0]
    for key in ("measured", "joined", "all"):
        assert math.isfinite(row[key]) and row[key] > 0, row
    assert row["rounds"] and row["rounds"][0][0] == 0, row
    assert "all cells: joined / measured" in r.stdout
