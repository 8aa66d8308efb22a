"""`flybo baselines verify`'s rules on hand-made runs: what counts as agreeing in the exact
preset (identical) and in the others (within the cell's measured spread), and which cells are
sampled. Re-flying real cells is in tests/server/test_baselines_suite.py."""

from __future__ import annotations

import base64
from typing import Any

import numpy as np
import pytest

from flybo.baselines_verify import FLOOR, compare_exact, compare_spread, sample_cells
from server.baseline_format import ResultEntry, RunEntry, SeriesEntry


def _series(volume: list[float]) -> SeriesEntry:
    def b64(values: list[float]) -> str:
        return base64.b64encode(np.asarray(values, dtype="<f4").tobytes()).decode()

    return SeriesEntry(time_s=b64(list(range(len(volume)))), explored_volume_m3=b64(volume),
                       recall_time_s=b64([20.0]), surface_recall=b64([0.5]))


def _run(seed: int, coverage: float, *, preset: str = "default", planner: str = "a-v1",
         area: str = "maze", **result: Any) -> RunEntry:
    fields: dict[str, Any] = dict(
        outcome="succeeded", reason="time limit reached", simulated_until_s=20.0,
        explored_volume_m3=100 * coverage, volume_at_plateau_m3=100 * coverage,
        observable_volume_m3=100.0, coverage=coverage, volumetric_efficiency=5 * coverage,
        precision=0.9, recall=0.8, fscore=0.85, rmse_m=0.02, collisions=0,
        path_length_m=12.0, iterations=7, planning_ms_median=3.0, planning_ms_mean=4.0,
        planning_ms_max=9.0, wall_seconds=10.0, benchmark_version="v", record={"seed": seed},
        metrics={"coverage": coverage})
    fields.update(result)
    return RunEntry(planner=planner, area=area, seed=seed, preset=preset, seconds=20.0,
                    attempts=1, sim_time_s=20.0, enqueued_at=None, started_at=None,
                    finished_at=None, wall_time_s=10.0, result=ResultEntry(**fields),
                    series=_series([0.0, 50 * coverage, 100 * coverage]))


def test_exact_means_identical_but_for_the_wall_clock() -> None:
    stored = _run(0, 0.5, preset="exact")
    again = stored.result.model_copy(update={"wall_seconds": 99.0, "planning_ms_max": 1.0,
                                             "record": {"machine": "other"}})
    assert all(c.ok for c in compare_exact(stored, again, stored.series))
    off = stored.result.model_copy(update={"path_length_m": 12.000001})
    bad = [c.what for c in compare_exact(stored, off, stored.series) if not c.ok]
    assert bad == ["path_length_m"]
    other_series = _series([0.0, 25.0, 50.000004])
    bad = [c.what for c in compare_exact(stored, stored.result, other_series) if not c.ok]
    assert bad == ["series explored_volume_m3"]


def test_other_presets_agree_within_the_cells_spread() -> None:
    cell = [_run(0, 0.60), _run(1, 0.70), _run(2, 0.66)]
    # The cell's spread: 0.10 in coverage.
    near = cell[1].result.model_copy(update={"coverage": 0.79, "explored_volume_m3": 79.0})
    checks = {c.what: c for c in compare_spread(cell, cell[1], near)}
    assert checks["coverage"].ok and checks["coverage"].tolerance == pytest.approx(0.10)
    far = cell[1].result.model_copy(update={"coverage": 0.81})
    assert not {c.what: c for c in compare_spread(cell, cell[1], far)}["coverage"].ok
    # Runs that agree to the last digit: the floor, 1 % of the mean, stands in for the spread.
    flat = [_run(s, 0.999) for s in range(3)]
    checks = {c.what: c for c in compare_spread(flat, flat[0], flat[0].result.model_copy(
        update={"coverage": 0.999 - 0.5 * FLOOR * 0.999}))}
    assert checks["coverage"].ok and checks["coverage"].tolerance == pytest.approx(0.00999)
    # An F-score only one of them has is a disagreement; none on both sides is not.
    gone = cell[0].result.model_copy(update={"fscore": None})
    assert not {c.what: c for c in compare_spread(cell, cell[0], gone)}["fscore"].ok


def test_cells_are_sampled_by_seed_and_preset() -> None:
    runs = [_run(s, 0.5, planner=p, area=a, preset=pr) for p in ("a-v1", "b-v1")
            for a in ("maze", "hall") for pr in ("exact", "default") for s in range(3)]
    picked = sample_cells(runs, 3, seed=1)
    assert len(picked) == 3 and len({r.cell for _, r in picked}) == 3
    assert all(all(x.cell == run.cell for x in cell) and len(cell) == 3 for cell, run in picked)
    assert [r.cell for _, r in picked] == [r.cell for _, r in sample_cells(runs, 3, seed=1)]
    exact = sample_cells(runs, 10, seed=0, presets=["exact"])
    assert len(exact) == 4 and {r.preset for _, r in exact} == {"exact"}
