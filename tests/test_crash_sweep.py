"""benchmarks/crash_sweep.py: a run's log line carries the scores `benchmarks/paper_findings.py`
compares (coverage, and the surface's F-score, precision, recall and RMSE), and the paper's
surface findings are measured from such lines."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.crash_sweep import _run
from benchmarks.paper_findings import compare, sweep_runs
from benchmarks.paper_reference import PLANNERS


def test_a_run_logs_its_surface_scores(tmp_path: Path) -> None:
    run = _run("classic", "maze", 0, 10.0, "test-1", str(tmp_path))
    assert run["status"] == "succeeded" and run["benchmark"] == "test-1"
    precision, recall = run["precision"], run["recall"]
    assert 0.0 < recall <= 1.0 and 0.0 < precision <= 1.0
    assert run["fscore"] == pytest.approx(2 * precision * recall / (precision + recall))
    assert run["rmse_m"] > 0.0
    assert (tmp_path / run["recording"]).exists()
    assert run["speed_factor"] > 0.0  # the machine's speed the charge read
    json.dumps(run)  # one log line


def test_surface_findings_are_measured_from_runs_that_log_them(tmp_path: Path) -> None:
    from flybo.versions import benchmark_version
    from planners.registry import spec

    here = benchmark_version()
    rows = []
    for i, name in enumerate(PLANNERS):
        for area in ("maze", "warehouse"):
            rows.append({"planner": spec(name).id, "area": area, "seed": 0, "seconds": None,
                         "benchmark": here, "coverage": 0.99 - 0.01 * i,
                         "fscore": 0.9 - 0.01 * i, "precision": 0.9, "recall": 0.95 - 0.01 * i,
                         "rmse_m": 0.02 + 0.001 * i, "collisions": 0})
    log = tmp_path / "crash_sweep.jsonl"
    log.write_text("".join(json.dumps(r) + "\n" for r in rows))
    summary = compare(sweep_runs(log, None))
    assert summary["kendall_tau"]["rmse"] is not None
    statuses = {f["finding"]: f["status"] for f in summary["findings"]}
    assert statuses["ESM-IPP has the best RMSE (best average RMSE rank)"] != "not measured"
    assert statuses["surface coverage: NBVP is the worst overall (lowest mean surface recall)"] \
        != "not measured"
