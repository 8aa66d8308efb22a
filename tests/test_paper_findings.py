"""benchmarks/paper_findings.py: the transcription of the paper's Tables 2 and 3 (checked
against the averages the paper prints), the findings' tests on the paper's own numbers, and the
comparison of a set of runs."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import pytest

# The benchmark scripts are not an installed package: they run from the project folder.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from benchmarks.paper_findings import compare, our_cells, paper_cells, sweep_runs, tau_intervals
from benchmarks.paper_reference import (
    AREAS,
    PAPER_TABLE2,
    PAPER_TABLE3_FSCORE,
    PLANNERS,
    average_ranks,
    findings,
)

# The paper's own "Average" and "Avg. rank" columns of Tables 2 and 3.
PRINTED_AVERAGE = {"classic": 0.9579, "rapid": 0.9945, "nbvp": 0.9744, "aep": 0.9847,
                   "esm-ipp": 0.9981, "esm-recon": 0.9858, "splatplanner": 0.9974}
PRINTED_FSCORE_AVERAGE = {"classic": 0.8755, "rapid": 0.9034, "nbvp": 0.8736, "aep": 0.8786,
                          "esm-ipp": 0.8942, "esm-recon": 0.9064, "splatplanner": 0.9}
PRINTED_RANK = {"classic": 5.3, "rapid": 3.7, "nbvp": 5.8, "aep": 5.5, "esm-ipp": 2.2,
                "esm-recon": 2.9, "splatplanner": 2.6}
PRINTED_FSCORE_RANK = {"classic": 3.9, "rapid": 2.8, "nbvp": 5.8, "aep": 5.8, "esm-ipp": 3.6,
                       "esm-recon": 2.7, "splatplanner": 3.3}


def test_the_transcribed_tables_give_the_paper_s_averages_and_ranks() -> None:
    for planner in PLANNERS:
        assert sum(PAPER_TABLE2[planner]) / len(AREAS) == pytest.approx(
            PRINTED_AVERAGE[planner], abs=1.5e-4)
        assert sum(PAPER_TABLE3_FSCORE[planner]) / len(AREAS) == pytest.approx(
            PRINTED_FSCORE_AVERAGE[planner], abs=1.5e-4)
    cells = paper_cells(list(PLANNERS), list(AREAS))
    for key, printed in (("relative", PRINTED_RANK), ("fscore", PRINTED_FSCORE_RANK)):
        got = average_ranks(cells, key)
        for planner, rank in printed.items():
            assert got[planner] == pytest.approx(rank, abs=0.1), (key, planner)


def test_every_finding_the_tables_can_show_holds_on_the_paper_s_numbers() -> None:
    result = findings(paper_cells(list(PLANNERS), list(AREAS)))
    assert len(result) >= 15
    for f in result:
        if "surface coverage" in f["finding"]:  # Figure 5, not in the tables
            assert f["status"] == "not measured"
        else:
            assert f["status"] == "held", f["finding"]


def _run(planner: str, area: str, volume: float, fscore: float, seed: int = 0
         ) -> dict[str, Any]:
    return {"planner": planner, "area": area, "seed": seed, "coverage": volume / 100.0,
            "explored_observable_m3": volume, "fscore": fscore, "rmse_m": 0.03,
            "recall": fscore}


def test_a_subset_is_compared_over_its_own_planners_and_areas() -> None:
    runs = [_run("esm-ipp-v2", "warehouse", 98.0, 0.8), _run("esm-ipp-v2", "warehouse", 96.0,
                                                             0.8, seed=1),
            _run("splatplanner-v2", "warehouse", 100.0, 0.7),
            _run("esm-ipp-v2", "powerplant", 50.0, 0.96),
            _run("splatplanner-v2", "powerplant", 40.0, 0.95)]
    cells = our_cells(runs)
    assert cells["esm-ipp"]["warehouse"]["relative"] == pytest.approx(0.97)
    assert cells["splatplanner"]["warehouse"]["relative"] == pytest.approx(1.0)
    assert cells["splatplanner"]["powerplant"]["relative"] == pytest.approx(0.8)
    summary = compare(runs)
    assert summary["areas"] == ["warehouse", "powerplant"]
    assert summary["average_ranks"]["relative"]["ours"] == {"esm-ipp": 1.5,
                                                            "splatplanner": 1.5}
    assert summary["average_ranks"]["relative"]["paper"]["esm-ipp"] < \
        summary["average_ranks"]["relative"]["paper"]["splatplanner"]
    statuses = {f["finding"]: f["status"] for f in summary["findings"]}
    assert statuses["the Pareto set is ESM-IPP, ESM-Recon and SplatPlanner"] == "not measured"
    assert summary["kendall_tau"]["fscore"] == pytest.approx(-1.0)


def _sweep_row(planner: str, area: str, coverage: float, fscore: float,
               benchmark: str) -> dict[str, Any]:
    """A run as `benchmarks/crash_sweep.py` logs it: no explored volume, RMSE or recall."""
    return {"planner": planner, "area": area, "seed": 0, "seconds": None,
            "benchmark": benchmark, "coverage": coverage, "fscore": fscore, "collisions": 0}


def test_a_crash_sweep_log_is_compared_on_coverage_and_fscore_alone(tmp_path: Path) -> None:
    from flybo.versions import benchmark_version
    from planners.registry import spec

    here = benchmark_version()
    latest = {name: spec(name).id for name in PLANNERS}  # each family's default version
    rows = [_sweep_row(latest[p], area, 0.99 - 0.01 * i, 0.9 - 0.01 * i, here)
            for i, p in enumerate(PLANNERS) for area in ("maze", "warehouse")]
    older = [_sweep_row(latest["classic"], "maze", 1.0, 1.0, "2000.01-1"),
             _sweep_row("classic-v1", "maze", 1.0, 1.0, here),  # not the name's version now
             _sweep_row(latest["classic"], "cafe", 1.0, 1.0, here)]  # not a paper area
    log = tmp_path / "crash_sweep.jsonl"
    log.write_text("".join(json.dumps(r) + "\n" for r in rows + older))

    runs = sweep_runs(log, None)
    assert sorted(map(json.dumps, runs)) == sorted(map(json.dumps, rows))
    summary = compare(runs)
    # Coverage stands in for the explored volume: the same ratios within an area.
    assert summary["ours"]["classic"]["maze"]["relative"] == pytest.approx(1.0)
    assert summary["ours"]["rapid"]["maze"]["relative"] == pytest.approx(0.98 / 0.99)
    assert "rmse" not in summary["ours"]["classic"]["maze"]
    assert summary["kendall_tau"]["rmse"] is None
    assert summary["kendall_tau"]["relative"] is not None
    statuses = {f["finding"]: f["status"] for f in summary["findings"]}
    assert statuses["ESM-IPP has the best RMSE (best average RMSE rank)"] == "not measured"
    assert statuses["ESM-IPP is the clear coverage winner (best average coverage rank)"] == \
        "not held"

    with pytest.raises(SystemExit, match=r"no run of benchmark 1999\.01-1"):
        sweep_runs(log, "1999.01-1")


def _paper_ordered_runs(spread: float, seeds: int) -> list[dict[str, Any]]:
    """Runs on two areas whose mean coverage follows the paper's Table 2 order exactly, each
    seed moved by up to `spread` m³ around it."""
    rng = np.random.default_rng(1)
    runs = []
    for area in ("maze", "warehouse"):
        column = AREAS.index(area)
        for planner in PLANNERS:
            mean = 1000.0 * PAPER_TABLE2[planner][column]
            for seed, shift in enumerate(np.linspace(-spread, spread, seeds)):
                runs.append(_run(f"{planner}-v9", area, mean + shift + rng.uniform(0, 1e-6),
                                 PAPER_TABLE3_FSCORE[planner][column], seed))
    return runs


def test_tau_intervals_are_narrow_when_seeds_agree_and_wide_when_they_do_not() -> None:
    steady = tau_intervals(_paper_ordered_runs(0.01, 5), 200, np.random.default_rng(0))
    assert steady["relative"]["p5"] == pytest.approx(compare(
        _paper_ordered_runs(0.01, 5))["kendall_tau"]["relative"], abs=0.05)
    assert steady["relative"]["p95"] - steady["relative"]["p5"] < 0.1
    assert steady["relative"]["replicates"] == 200
    noisy = tau_intervals(_paper_ordered_runs(30.0, 5), 200, np.random.default_rng(0))
    assert noisy["relative"]["p95"] - noisy["relative"]["p5"] > 0.3
    assert 0.0 <= noisy["relative"]["share_at_target"] <= 1.0
    # The same draws give the same interval; one run per cell gives none.
    again = tau_intervals(_paper_ordered_runs(30.0, 5), 200, np.random.default_rng(0))
    assert again == noisy
    assert tau_intervals(_paper_ordered_runs(30.0, 1), 200, np.random.default_rng(0)) == {}


def test_several_sweep_logs_are_read_and_a_run_in_two_counts_once(tmp_path: Path) -> None:
    from flybo.versions import benchmark_version
    from planners.registry import spec

    here = benchmark_version()
    latest = {name: spec(name).id for name in PLANNERS}
    first = [_sweep_row(latest[p], "maze", 0.9, 0.8, here) for p in PLANNERS]
    second = [_sweep_row(latest[p], "warehouse", 0.8, 0.7, here) for p in PLANNERS]
    a, b = tmp_path / "a.jsonl", tmp_path / "b.jsonl"
    a.write_text("".join(json.dumps(r) + "\n" for r in first))
    b.write_text("".join(json.dumps(r) + "\n" for r in [*second, first[0]]))
    runs = sweep_runs([a, b], None)
    assert sorted(map(json.dumps, runs)) == sorted(map(json.dumps, first + second))
    with pytest.raises(SystemExit, match=r"a\.jsonl: no run of benchmark 2000\.01-1"):
        sweep_runs([a], "2000.01-1")


def test_the_sweeps_runs_are_taken_on_the_areas_and_seeds_asked_for(tmp_path: Path) -> None:
    import subprocess
    import sys

    from flybo.versions import benchmark_version
    from planners.registry import spec

    here = benchmark_version()
    latest = {name: spec(name).id for name in PLANNERS}
    rows = [{**_sweep_row(latest[p], area, 0.9, 0.8, here), "seed": seed}
            for p in PLANNERS for area in ("maze", "warehouse") for seed in (0, 1)]
    log = tmp_path / "runs.jsonl"
    log.write_text("".join(json.dumps(r) + "\n" for r in rows))
    root = Path(__file__).resolve().parents[1]
    done = subprocess.run(
        [sys.executable, str(root / "benchmarks" / "paper_findings.py"), "--sweep", str(log),
         "--areas", "maze", "--seeds", "1", "--bootstrap", "0", "--name", "paper_findings_test"],
        capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    written = json.loads((root / "benchmarks" / "results" / "paper_findings_test.json").read_text())
    assert {(r["area"], r["seed"]) for r in written["runs"]} == {("maze", 1)}
    assert len(written["runs"]) == len(PLANNERS)
    refused = subprocess.run(
        [sys.executable, str(root / "benchmarks" / "paper_findings.py"), "--sweep", str(log),
         "--seeds", "7", "--bootstrap", "0", "--name", "paper_findings_test"],
        capture_output=True, text=True, check=False)
    assert refused.returncode != 0 and "no run of the sweeps" in refused.stderr


def test_loaded_runs_replace_the_sweep_s_of_their_planner_and_area(tmp_path: Path) -> None:
    import argparse

    from benchmarks.paper_findings import gathered_runs
    from flybo.versions import benchmark_version
    from planners.registry import spec

    here = benchmark_version()
    latest = {name: spec(name).id for name in PLANNERS}
    swept = [{**_sweep_row(latest[p], area, 0.9, 0.8, here), "seed": seed} for p in PLANNERS
             for area in ("maze", "warehouse") for seed in (0, 1)]
    log = tmp_path / "runs.jsonl"
    log.write_text("".join(json.dumps(r) + "\n" for r in swept))
    # Runs flown with another camera (as sensor_range.py writes them), on WAREHOUSE, one seed.
    other = [{"planner": latest[p], "area": "warehouse", "seed": 0, "coverage": 0.99,
              "fscore": 0.7, "camera_range_m": 7.0} for p in PLANNERS]
    loaded = tmp_path / "camera.json"
    loaded.write_text(json.dumps({"runs": other}))
    args = argparse.Namespace(load=[loaded], sweep=[log], benchmark=None,
                              areas=["maze", "warehouse"], seeds=None)
    runs = gathered_runs(args)
    # WAREHOUSE's cells hold the loaded run alone, not the sweep's two seeds beside it.
    assert sorted((r["area"], r["seed"], "camera_range_m" in r) for r in runs) == sorted(
        [("maze", s, False) for _ in PLANNERS for s in (0, 1)]
        + [("warehouse", 0, True) for _ in PLANNERS])
    summary = compare(runs)
    assert set(summary["areas"]) == {"maze", "warehouse"}


def test_records_are_loaded_and_another_benchmark_version_refused(tmp_path: Path) -> None:
    import argparse

    from benchmarks.paper_findings import gathered_runs, loaded_runs
    from flybo.versions import benchmark_version
    from planners.registry import spec

    here = benchmark_version()
    runs = [{"benchmark": here, "planner": spec(p).id, "area": "powerplant", "seed": 0,
             "coverage": 0.99, "fscore": 0.7} for p in PLANNERS]
    record = tmp_path / "record.jsonl"
    record.write_text("".join(json.dumps(r) + "\n" for r in runs) + "\n")
    assert loaded_runs(record) == runs

    def args(benchmark: str | None) -> argparse.Namespace:
        return argparse.Namespace(load=[record], sweep=None, benchmark=benchmark,
                                  areas=list(AREAS), seeds=None)

    assert gathered_runs(args(None)) == runs
    with pytest.raises(SystemExit, match=r"benchmark .* not 2000\.01-1"):
        gathered_runs(args("2000.01-1"))
