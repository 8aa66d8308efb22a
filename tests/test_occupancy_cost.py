"""benchmarks/occupancy_cost.py: this tree standing in as its own baseline (loaded from a copy,
as another tree's kernel is), so the two maps must end equal to the bit."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_the_same_tree_as_baseline_gives_the_same_map() -> None:
    out = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "occupancy_cost.py"), "--baseline", str(ROOT)],
        cwd=ROOT, check=True, capture_output=True, text=True, timeout=600)
    assert "same map" in out.stdout
    report = json.loads((ROOT / "benchmarks" / "results" / "occupancy_cost.json").read_text())
    (scene,) = report["scenes"]
    assert scene["scene"] == "thin room" and scene["frames"] > 100
    assert scene["same_map"] is True
    assert scene["this_ms"] > 0.0 and scene["baseline_ms"] > 0.0


def test_a_baseline_without_the_kernel_is_refused(tmp_path: Path) -> None:
    out = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "occupancy_cost.py"), "--baseline",
         str(tmp_path)],
        cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert out.returncode != 0
    assert f"--baseline {tmp_path}: no sim/occupancy_kernels.py in it" in out.stderr
