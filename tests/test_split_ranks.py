"""benchmarks/split_ranks.py: published rows read back as runs, the public cell chosen per
planner family and area, and the two splits' ranks compared."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import pytest

# The benchmark scripts are not an installed package: they run from the project folder.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.paper_reference import AREAS, PLANNERS
from benchmarks.split_ranks import compare, heldout_runs, public_runs, published_runs

PAGE = """\
| planner | area | ended | coverage % | F-score % | collisions | safety stops | memory | CPU s |
| --- | --- | --- | --- | --- | --- | --- | --- | --- |
| `esm-ipp-v2` | PLATFORM-A | time limit | 72.8 | 78.0 | 0 | 0 | 799 | 81 |
| `esm-ipp-v2` | MAZE | time limit | 99.6 | 89.9 | 0 | 0 | 660 | 104 |
| `classic-v2` | MAZE | 543 s: no frontier can be seen | 100.0 | 89.4 | 0 | 1 | 674 | 48 |

Later, another flight of the same run:

| `classic-v2` | MAZE | time limit | 90.0 | 80.0 | 0 | 0 | 674 | 48 |
| `esm-ipp-v3` | PLATFORM-A | time limit | 99.4 | 87.8 | 0 | 0 | 871 | 105 |
"""


def _run(planner: str, area: str, coverage: float, **extra: Any) -> dict[str, Any]:
    return {"planner": planner, "area": area, "coverage": coverage, "fscore": 0.8,
            "collisions": 0, "safety_stops": 0, "status": "succeeded", **extra}


def test_published_rows_are_read_as_runs(tmp_path: Path) -> None:
    page = tmp_path / "RESULTS.md"
    page.write_text(PAGE)
    runs = published_runs(page)
    assert [(r["planner"], r["area"]) for r in runs] == [
        ("esm-ipp-v2", "platform-a"), ("esm-ipp-v2", "maze"), ("classic-v2", "maze"),
        ("classic-v2", "maze"), ("esm-ipp-v3", "platform-a")]
    assert runs[2]["coverage"] == pytest.approx(1.0)
    assert runs[2]["safety_stops"] == 1
    assert runs[2]["status"] == "543 s: no frontier can be seen"


def test_a_public_cell_is_the_newest_version_s_first_row_unless_the_log_has_one(
        tmp_path: Path) -> None:
    page = tmp_path / "RESULTS.md"
    page.write_text(PAGE)
    chosen = {(r["planner"], r["area"]): r["coverage"]
              for r in public_runs([], published_runs(page))}
    assert chosen == {("esm-ipp-v3", "platform-a"): pytest.approx(0.994),
                      ("esm-ipp-v2", "maze"): pytest.approx(0.996),
                      ("classic-v2", "maze"): pytest.approx(1.0)}
    logged = [_run("classic-v2", "maze", 0.95), _run("classic-v2", "maze@7", 0.9)]
    chosen = {(r["planner"], r["area"]): r["coverage"]
              for r in public_runs(logged, published_runs(page))}
    assert chosen[("classic-v2", "maze")] == pytest.approx(0.95)


def test_held_out_runs_are_the_newest_versions_on_other_layouts() -> None:
    from planners.registry import spec

    newest = spec("classic").id
    logged = [_run(newest, "maze@7", 0.9), _run(newest, "maze", 1.0),
              _run("classic-v1", "maze@7", 0.5), _run(newest, "cafe@3", 0.5)]
    runs = heldout_runs(logged)
    assert [(r["planner"], r["area"], r["layout"]) for r in runs] == [(newest, "maze", "maze@7")]


def test_the_same_order_on_both_splits_has_tau_one_and_a_reversed_one_minus_one() -> None:
    planners = list(PLANNERS)
    areas = list(AREAS[:3])
    public = [_run(f"{p}-v9", a, 0.9 + 0.01 * i) for i, p in enumerate(planners) for a in areas]
    same = [_run(f"{p}-v9", a, 0.5 + 0.05 * i) for i, p in enumerate(planners) for a in areas]
    reversed_ = [_run(f"{p}-v9", a, 0.9 - 0.01 * i) for i, p in enumerate(planners)
                 for a in areas]
    summary = compare(public, same)
    assert summary["kendall_tau"] == pytest.approx(1.0)
    assert summary["missing"] == []
    assert summary["gap_pp"]["classic"] == pytest.approx(40.0)
    assert compare(public, reversed_)["kendall_tau"] == pytest.approx(-1.0)


def test_differences_below_the_published_precision_are_ties() -> None:
    areas = list(AREAS[:2])
    public = [_run("classic-v9", a, 0.9991) for a in areas] + \
        [_run("rapid-v9", a, 0.9994) for a in areas]
    summary = compare(public, public)
    ranks = summary["average_coverage_rank"]["public"]
    assert ranks["classic"] == ranks["rapid"]
    assert summary["missing"] == []
