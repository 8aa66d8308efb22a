"""benchmarks/stage_peaks.py: a short run's stages and its TSDF block table, as it reports them
(in a process of its own: the benchmark wraps the simulator's stages to watch them)."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

from sim.config import preset
from sim.tsdf import EXPECTED_BLOCK_MARGIN

ROOT = Path(__file__).resolve().parents[1]


def test_a_short_run_reports_each_stage_and_the_block_table() -> None:
    out = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "stage_peaks.py"), "--planner", "classic",
         "--area", "maze", "--seconds", "20", "--out", "stage_peaks_test"],
        cwd=ROOT, check=True, capture_output=True, text=True, timeout=600)
    assert "highest resident set per stage" in out.stdout
    report = json.loads((ROOT / "benchmarks" / "results" / "stage_peaks_test.json").read_text())
    stages = report["stages"]
    for stage in ("camera frame", "planner call", "final measures", "recording save"):
        assert stage in stages, stage
        assert stages[stage]["highest_mib"] >= stages[stage]["rise_mib"] >= 0
    table = report["block_table"]
    assert table["expected"] > 0
    assert table["capacity"] == max(preset("default").tsdf.initial_block_count,
                                    math.ceil(table["expected"] * EXPECTED_BLOCK_MARGIN))
    assert table["growths"] == []  # a few seconds fill a fraction of the table
    assert 0 < table["final_blocks"] < table["capacity"]
    assert table["frames"] > 0
