"""Curves of each planner on one area: explored volume and surface recall over time, over runs.

The paper's Figures 4 and 5 draw, per area, one line per planner (the mean over runs) with a
band from the smallest to the largest run. Runs of one planner may have been asked for different
lengths: each time point aggregates the runs that reached it, so a band never mixes in a run
that had already stopped. Like the leaderboard, the curves are of one benchmark version's runs.
"""

from __future__ import annotations

from collections import defaultdict
from typing import Annotated

import numpy as np
import numpy.typing as npt
from fastapi import APIRouter, HTTPException, Query, Request
from sqlalchemy import select
from sqlalchemy.orm import Session

from server.benchmark_versions import UnknownBenchmarkVersionError, check_known, current_version
from server.deps import SessionDep
from server.models import AreaRow, MetricSeries, PlannerRow, Run
from server.result_queries import succeeded_results
from server.schemas import Band, Curves, ErrorBody, PlannerCurves

router = APIRouter(tags=["leaderboard"])

Floats = npt.NDArray[np.float64]
MAX_POINTS = 2000


def _floats(blob: bytes) -> Floats:
    return np.frombuffer(blob, dtype="<f4").astype(np.float64)


def _band(runs: list[tuple[Floats, Floats]], grid: Floats) -> Band:
    """Mean, min and max at each grid time over the runs whose samples reach that time."""
    stacked = np.full((len(runs), len(grid)), np.nan)
    for i, (t, v) in enumerate(runs):
        if len(t) == 0:
            continue
        inside = grid <= t[-1] + 1e-6
        stacked[i, inside] = np.interp(grid[inside], t, v)
    seen = ~np.isnan(stacked).all(axis=0)
    mean, low, high = (np.full(len(grid), np.nan) for _ in range(3))
    if seen.any():
        mean[seen] = np.nanmean(stacked[:, seen], axis=0)
        low[seen] = np.nanmin(stacked[:, seen], axis=0)
        high[seen] = np.nanmax(stacked[:, seen], axis=0)
    return Band(mean=_list(mean), min=_list(low), max=_list(high))


def _list(values: Floats) -> list[float | None]:
    return [None if np.isnan(v) else round(float(v), 6) for v in values]


def _times(values: Floats) -> list[float]:
    return [round(float(v), 3) for v in values]


def _grid(runs: list[tuple[Floats, Floats]], max_points: int) -> Floats:
    """The longest run's sample times, thinned to at most `max_points` (keeping the last)."""
    longest = max((t for t, _ in runs), key=len, default=np.zeros(0))
    if len(longest) <= max_points:
        return longest
    picks = np.unique(np.r_[np.linspace(0, len(longest) - 1, max_points).round().astype(int)])
    return longest[picks]


def build_curves(session: Session, preset: str, area: str, max_points: int, *,
                 benchmark_version: str) -> Curves:
    query = (succeeded_results(PlannerRow.name, PlannerRow.version, PlannerRow.builtin,
                               MetricSeries, preset=preset, benchmark_version=benchmark_version)
             .join(MetricSeries, MetricSeries.run_id == Run.id).where(AreaRow.name == area))
    groups: dict[tuple[str, bool], list[MetricSeries]] = defaultdict(list)
    for name, version, builtin, series in session.execute(query):
        groups[(f"{name}-v{version}", builtin)].append(series)
    planners = []
    for (planner, builtin), members in sorted(groups.items()):
        volume = [(_floats(s.time_s), _floats(s.explored_volume_m3)) for s in members]
        recall = [(_floats(s.recall_time_s), _floats(s.surface_recall)) for s in members]
        vgrid, rgrid = _grid(volume, max_points), _grid(recall, max_points)
        planners.append(PlannerCurves(
            planner=planner, builtin=builtin, runs=len(members),
            time_s=_times(vgrid), explored_volume_m3=_band(volume, vgrid),
            recall_time_s=_times(rgrid), surface_recall=_band(recall, rgrid),
        ))
    plateau = session.scalar(select(AreaRow.plateau_s).where(AreaRow.name == area))
    return Curves(preset=preset, benchmark_version=benchmark_version, area=area,
                  plateau_s=plateau, planners=planners)


@router.get("/curves", response_model=Curves, responses={404: {"model": ErrorBody}})
def curves(
    request: Request,
    session: SessionDep,
    area: Annotated[str, Query(max_length=40, description="area name, e.g. maze")],
    preset: Annotated[str, Query(max_length=32)] = "default",
    max_points: Annotated[int, Query(ge=10, le=20_000,
                                     description="most points per curve")] = MAX_POINTS,
    benchmark_version: Annotated[str | None, Query(
        max_length=64, description="the benchmark version whose runs are drawn; default: the "
        "current one")] = None,
) -> Curves:
    """Per planner on `area`: explored volume and surface recall over time, mean/min/max, over
    the runs of one benchmark version."""
    if session.scalar(select(AreaRow.id).where(AreaRow.name == area)) is None:
        raise HTTPException(404, f"no area named {area!r}")
    current = current_version(request.app.state, session)
    version = benchmark_version or current
    try:
        check_known(session, version, current)
    except UnknownBenchmarkVersionError as exc:
        raise HTTPException(404, str(exc)) from None
    return build_curves(session, preset, area, max_points, benchmark_version=version)
