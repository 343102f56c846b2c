"""End-to-end test of ``benches/slow_camera.py`` on a tiny grid (one system, one seed, gain 1,
cameras 100 and 30:0.1, short logs): the table's shape, and ratios finite and positive.

    pytest benches/test_slow_camera_bench.py   # HBN_BIN=/path/to/hbn, else target/release/hbn

Skips, saying so, without the ``hbn`` binary or the hbn wheel (which reads the test log).
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
SCRIPT = HERE / "slow_camera.py"
HBN = Path(os.environ.get("HBN_BIN") or HERE.parent / "target" / "release" / "hbn")


def _run(args: list, tmp_path: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(SCRIPT), "--hbn", str(HBN), *args], capture_output=True, text=True, cwd=tmp_path, timeout=900)


def test_a_tiny_grid_prints_a_row_per_camera_and_finite_ratios(tmp_path: Path) -> None:
    if not HBN.is_file():
        pytest.skip(f"no hbn binary at {HBN}: build it with `cargo build --release -p hbn-cli` or set HBN_BIN")
    pytest.importorskip("hbn", reason="the hbn wheel reads the test log's true state (pip install ./hbn-py)")
    out = tmp_path / "rows.json"
    args = ["--systems", "duhem", "--gains", "1", "--seeds", "1", "--steps", "500", "--test-steps", "400", "--cameras", "100,30:0.1,100@3", "--json", str(out)]
    p = _run(args, tmp_path)
    assert p.returncode == 0, p.stdout + p.stderr
    lines = p.stdout.splitlines()
    for key in ("- machine: ", "- date: ", "- command: ", "- hbn: "):
        assert any(line.startswith(key) for line in lines), key

    # The per-cell table: its header, a separator, then one row per camera.
    start = lines.index("| system | gain | seed | camera | frames kept | nRMSE | cov. 2σ | train s |")
    rows = []
    for line in lines[start + 2 :]:
        if not line.startswith("|"):
            break
        rows.append([c.strip() for c in line.strip("|").split("|")])
    assert [r[:4] for r in rows] == [["duhem", "1", "1", "100"], ["duhem", "1", "1", "30:0.1"], ["duhem", "1", "1", "100@3"]]
    assert rows[0][4] == "500 of 500" and rows[2][4] == "500 of 500"
    kept, taken = (int(v) for v in rows[1][4].split(" of "))
    assert taken == 150 and 0 < kept < taken  # 4.99 s at 30 Hz
    for r in rows:
        nrmse, cov, secs = float(r[5]), float(r[6]), float(r[7])
        assert 0.0 < nrmse < 1.0 and 0.0 <= cov <= 1.0 and secs > 0.0, r

    # The summary: per camera, ratios to the 100 Hz camera, finite and positive.
    start = lines.index("| camera | cells | geo. mean nRMSE / nRMSE(100 Hz) | largest cell ratio | cells above 1.2 | mean train-time ratio |")
    summary = [[c.strip() for c in line.strip("|").split("|")] for line in lines[start + 2 : start + 5]]
    assert [s[0] for s in summary] == ["100", "30:0.1", "100@3"]
    assert summary[0][2:] == ["1.000", "1.000", "0", "1.00"]
    for s in summary:
        assert s[1] == "1"
        assert s[4] == ("1" if float(s[3]) > 1.2 else "0"), s
        for v in s[2:4] + s[5:]:
            assert math.isfinite(float(v)) and float(v) > 0.0, s

    doc = json.loads(out.read_text())
    assert len(doc["rows"]) == 3 and not any("error" in r for r in doc["rows"])
    assert [r["camera"] for r in doc["rows"]] == ["100", "30:0.1", "100@3"]
    assert [r["train_seed"] for r in doc["rows"]] == [None, None, 3]
    assert doc["rows"][1]["frames_taken"] == 150
    for s in doc["summary"]:
        for k in ("geo_mean_nrmse_ratio", "max_nrmse_ratio", "mean_train_time_ratio"):
            assert math.isfinite(s[k]) and s[k] > 0.0, s
    assert doc["header"]["protocol"]["cameras"] == ["100", "30:0.1", "100@3"]


def test_a_multi_signal_system_is_scored_per_component(tmp_path: Path) -> None:
    if not HBN.is_file():
        pytest.skip(f"no hbn binary at {HBN}: build it with `cargo build --release -p hbn-cli` or set HBN_BIN")
    hbn = pytest.importorskip("hbn", reason="the hbn wheel reads the test log's true state (pip install ./hbn-py)")
    out = tmp_path / "rows.json"
    args = ["--systems", "finger", "--gains", "1", "--seeds", "1", "--steps", "600", "--test-steps", "300", "--cameras", "100,30:0.1", "--json", str(out)]
    p = _run(args, tmp_path)
    assert p.returncode == 0, p.stdout + p.stderr
    doc = json.loads(out.read_text())
    assert [r["camera"] for r in doc["rows"]] == ["100", "30:0.1"]
    assert not any("error" in r for r in doc["rows"]), doc["rows"]
    # The cell's nRMSE is the mean of the components' against the test log's true state.
    test_log = tmp_path / "test.mcap"
    subprocess.run([str(HBN), "simulate", "--system", "finger", "--steps", "300", "--seed", "1001", "--noise-gain", "1.0", "--out", str(test_log)], check=True, capture_output=True)
    sys.path.insert(0, str(HERE))
    import slow_camera

    x_true, rate = slow_camera.read_truth("finger", test_log)
    assert x_true.shape == (300, 2) and rate == 100.0
    nrmse, cov = slow_camera.score(x_true + 0.01, x_true * 0 + 0.01, x_true)
    assert cov == 1.0 and 0.0 < nrmse < 0.1
    for r in doc["rows"]:
        assert 0.0 < r["nrmse"] < 1.0 and 0.0 <= r["coverage_2sigma"] <= 1.0, r
    assert "latent" in doc["rows"][1]["train_summary"]
    assert hbn.MULTI_SYSTEMS


def test_cameras_without_the_reference_or_malformed_are_usage_errors(tmp_path: Path) -> None:
    if not HBN.is_file():
        pytest.skip(f"no hbn binary at {HBN}")
    for cams, needle in (("30:0.1,10", "must hold 100"), ("100,30:1", "[0, 1)"), ("100,200", "(0, 100]"), ("100,fast", "RATE[:DROP][@SEED]"), ("100,100@x", "RATE[:DROP][@SEED]"), ("100,100@-1", ">= 0")):
        p = _run(["--cameras", cams], tmp_path)
        assert p.returncode == 2, (cams, p.stdout, p.stderr)
        assert "--cameras" in p.stderr and needle in p.stderr, (cams, p.stderr)


def test_the_summary_counts_cells_above_1_2_against_the_reference() -> None:
    np = pytest.importorskip("numpy")
    sys.path.insert(0, str(HERE))
    import slow_camera

    cams = [slow_camera.parse_camera(c) for c in ("100", "30:0.1", "100@2")]
    assert [c.is_reference for c in cams] == [True, False, False]
    assert (cams[2].rate, cams[2].drop, cams[2].train_seed) == (100.0, 0.0, 2)
    rows = []
    for seed, (ref, cam, again) in enumerate([(0.010, 0.013, 0.010), (0.020, 0.022, 0.025), (0.010, 0.005, 0.0121)]):
        for label, v in (("100", ref), ("30:0.1", cam), ("100@2", again)):
            rows.append({"system": "s", "gain": 1.0, "seed": seed, "camera": label, "nrmse": v, "train_seconds": 1.0})
    by = {s["camera"]: s for s in slow_camera.summarise(rows, cams)}
    assert by["100"]["cells_above_1_2"] == 0 and by["100"]["geo_mean_nrmse_ratio"] == 1.0
    # 1.3, 1.1, 0.5: one above 1.2.
    assert by["30:0.1"]["cells_above_1_2"] == 1 and by["30:0.1"]["max_nrmse_ratio"] == pytest.approx(1.3)
    assert by["30:0.1"]["geo_mean_nrmse_ratio"] == pytest.approx(float(np.cbrt(1.3 * 1.1 * 0.5)))
    # 1.0, 1.25, 1.21: two above 1.2.
    assert by["100@2"]["cells_above_1_2"] == 2
