"""benchmarks/suite_estimate.py: the suite's estimate from kept sweeps' runs, counting the
version each planner name stands for, a later log's run replacing an earlier's, and a missing
log refused."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from areas import area_names
from benchmarks.suite_estimate import _current, estimate, merged_runs, speed_factors

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "benchmarks" / "suite_estimate.py"


def _runs(planner: str, cpu_s: float) -> list[dict[str, object]]:
    return [{"planner": planner, "area": area, "seed": 0, "benchmark": "test-1", "cpu_s": cpu_s}
            for area in area_names()]


def test_the_estimate_is_cpu_time_times_runs_over_busy_cores() -> None:
    runs = [*_runs("classic-v2", 10.0)[:3], {**_runs("classic-v2", 99.0)[0], "seed": 1}]
    (row,) = estimate(runs, area_names(), repeats=5, busy_cores=2.0)
    assert row["planner"] == "classic-v2" and row["areas"] == 3
    assert row["cpu_s"] == pytest.approx(30.0)  # seed 1 stands for no area
    assert row["wall_min"] == pytest.approx(30.0 * 5 / 2.0 / 60)
    assert not row["complete"] and len(row["missing"]) == len(area_names()) - 3


def test_a_name_counts_the_version_it_stands_for() -> None:
    assert _current("classic-v2") == _current("classic")
    assert _current("classic-v1") != "classic-v1"
    assert _current("no-such-planner-v1") == "no-such-planner-v1"


def test_a_kept_log_is_read_and_an_older_version_listed_not_counted(tmp_path: Path) -> None:
    log = tmp_path / "runs.jsonl"
    current = _current("classic")
    older = "classic-v1"
    lines = _runs(current, 6.0) + _runs(older, 1000.0)
    log.write_text("".join(json.dumps(r) + "\n" for r in lines))
    command = [sys.executable, str(SCRIPT), "--benchmark", "test-1", "--log", str(log),
               "--busy-cores", "1", "--name", "suite_estimate_test"]
    done = subprocess.run(command, capture_output=True, text=True, cwd=tmp_path, check=False)
    assert done.returncode == 0, done.stderr
    assert older in done.stdout
    # 11 areas x 6 s x 5 runs / 1 core = 330 s: the older version's 1,000 s runs are not counted.
    assert f"all planners ({current}): 0.09 h" in done.stdout


def test_a_missing_log_is_refused(tmp_path: Path) -> None:
    done = subprocess.run([sys.executable, str(SCRIPT), "--log", str(tmp_path / "none.jsonl")],
                          capture_output=True, text=True, check=False)
    assert done.returncode != 0
    assert "none.jsonl: no such file" in done.stderr


def test_a_later_log_replaces_the_same_run_of_an_earlier_one(tmp_path: Path) -> None:
    first, second = _runs("classic-v2", 10.0), _runs("classic-v2", 4.0)[:2]
    merged = merged_runs([first, second])
    assert len(merged) == len(first)
    (row,) = estimate(merged, area_names(), repeats=1, busy_cores=1.0)
    assert row["cpu_s"] == pytest.approx(4.0 * 2 + 10.0 * (len(first) - 2))
    logs = []
    for name, runs in (("old.jsonl", first), ("new.jsonl", second)):
        logs.append(tmp_path / name)
        logs[-1].write_text("".join(json.dumps(r) + "\n" for r in runs))
    done = subprocess.run([sys.executable, str(SCRIPT), "--benchmark", "test-1", "--log",
                           *map(str, logs), "--busy-cores", "1", "--runs", "1",
                           "--name", "suite_estimate_test"],
                          capture_output=True, text=True, cwd=tmp_path, check=False)
    assert done.returncode == 0, done.stderr
    total = 10.0 * (len(first) - 2) + 8.0
    assert re.search(rf"classic-v2\s+{len(first)}/{len(first)}\s+{total:.0f}\s", done.stdout)


def test_the_speed_factors_of_the_runs_counted_are_stated(tmp_path: Path) -> None:
    classic, nbvp = _current("classic"), _current("nbvp")
    runs = [{**r, "speed_factor": 1.2 + 0.01 * n}
            for n, r in enumerate(_runs(classic, 5.0)[:4])]
    runs += [*_runs(classic, 5.0)[4:], {**_runs(nbvp, 5.0)[0], "speed_factor": 3.0}]
    runs += [{**_runs("classic-v1", 5.0)[0], "speed_factor": 9.0}]  # listed, not counted
    factors = speed_factors(runs, [classic])
    assert factors == {"least": 1.2, "largest": pytest.approx(1.23), "recorded": 4,
                       "runs": len(area_names())}
    assert speed_factors(runs, ["fuel-v2"])["least"] is None
    log = tmp_path / "runs.jsonl"
    log.write_text("".join(json.dumps(r) + "\n" for r in runs))
    done = subprocess.run([sys.executable, str(SCRIPT), "--benchmark", "test-1", "--log",
                           str(log), "--name", "suite_estimate_test"],
                          capture_output=True, text=True, cwd=tmp_path, check=False)
    assert done.returncode == 0, done.stderr
    assert f"1.20-3.00 (5 of {len(area_names()) + 1} runs record it)" in done.stdout
