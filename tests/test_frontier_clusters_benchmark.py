"""benchmarks/frontier_clusters.py: a short flight's clustering calls timed in two processes,
this tree standing in as its own baseline, so the two must report the same clusters."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_the_same_tree_as_baseline_gives_the_same_clusters() -> None:
    out = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "frontier_clusters.py"), "--area", "maze",
         "--seconds", "15", "--rounds", "1", "--baseline", str(ROOT),
         "--out", "frontier_clusters_test"],
        cwd=ROOT, check=True, capture_output=True, text=True, timeout=600)
    assert "the same clusters in both trees: yes" in out.stdout
    report = json.loads((ROOT / "benchmarks" / "results" / "frontier_clusters_test.json")
                        .read_text())
    assert report["same_clusters"] is True
    this, base = report["runs"]
    assert (this["tree"], base["tree"]) == ("this", "baseline")
    assert this["planner"] == "classic-v3" and this["preset"] == "exact"
    assert this["calls"] == base["calls"] > 0
    assert this["digest"] == base["digest"]
    assert 0 < this["median_ms"] <= this["max_ms"] <= this["total_ms"]
    assert len(report["ratios"]) == 1 and report["ratios"][0] > 0


def test_a_baseline_that_is_not_a_checkout_is_refused(tmp_path: Path) -> None:
    out = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "frontier_clusters.py"),
         "--baseline", str(tmp_path)],
        cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert out.returncode != 0
    assert f"--baseline {tmp_path}: not a checkout (no sim/ folder in it)" in out.stderr
