"""The leaderboard: per planner and area, mean/min/max over succeeded runs, and ranks.

Ranks follow the paper: per area, planners are ranked by mean coverage and by mean F-score
(1 is best, ties share the mean rank); the overall table averages them over the areas a planner
ran. Relative coverage is a run's explored volume at the plateau time over the best mean of any
planner on that area (`docs/metrics.md`).
"""

from __future__ import annotations

import threading
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from server.models import AreaRow, Job, PlannerRow, Run, RunResult, RunState
from server.schemas import Leaderboard, LeaderboardEntry, LeaderboardPlanner, Spread


@dataclass
class _Row:
    planner: str
    builtin: bool
    area: str
    result: RunResult


def spread(values: Sequence[float | None]) -> Spread:
    finite = [v for v in values if v is not None]
    if not finite:
        return Spread(mean=None, min=None, max=None)
    return Spread(mean=sum(finite) / len(finite), min=min(finite), max=max(finite))


def ranks(scores: dict[str, float]) -> dict[str, float]:
    """1 for the highest score; ties share the mean of their positions."""
    ordered = sorted(scores.items(), key=lambda kv: -kv[1])
    out: dict[str, float] = {}
    i = 0
    while i < len(ordered):
        j = i
        while j + 1 < len(ordered) and ordered[j + 1][1] == ordered[i][1]:
            j += 1
        for k in range(i, j + 1):
            out[ordered[k][0]] = (i + j) / 2 + 1
        i = j + 1
    return out


_cache: dict[tuple[str, str | None], tuple[tuple[int, int, int], Leaderboard]] = {}
_cache_lock = threading.Lock()


def build_leaderboard(session: Session, preset: str, area: str | None = None) -> Leaderboard:
    """The leaderboard, recomputed only when the stored results changed.

    The check is one indexed aggregate (count and highest id of finished runs, number of
    planners), so polling clients cost little; every API process keeps its own copy.
    """
    version_row = session.execute(
        select(func.count(Run.id), func.coalesce(func.max(Run.id), 0))
        .where(Run.status == RunState.SUCCEEDED.value, Run.preset == preset)).one()
    planners = session.scalar(select(func.count(PlannerRow.id))) or 0
    version = (int(version_row[0]), int(version_row[1]), int(planners))
    key = (preset, area)
    with _cache_lock:
        hit = _cache.get(key)
    if hit is not None and hit[0] == version:
        return hit[1].model_copy(deep=True)
    board = compute_leaderboard(session, preset, area)
    with _cache_lock:
        if len(_cache) > 256:
            _cache.clear()
        _cache[key] = (version, board)
    return board.model_copy(deep=True)


def compute_leaderboard(session: Session, preset: str, area: str | None = None) -> Leaderboard:
    query = (
        select(PlannerRow.name, PlannerRow.version, PlannerRow.builtin, AreaRow.name, RunResult)
        .join(Run, RunResult.run_id == Run.id)
        .join(Job, Run.job_id == Job.id)
        .join(PlannerRow, Job.planner_id == PlannerRow.id)
        .join(AreaRow, Run.area_id == AreaRow.id)
        .where(Run.status == RunState.SUCCEEDED.value, Run.preset == preset)
    )
    if area is not None:
        query = query.where(AreaRow.name == area)
    rows = [_Row(f"{name}-v{version}", builtin, area_name, result)
            for name, version, builtin, area_name, result in session.execute(query)]
    groups: dict[tuple[str, str], list[_Row]] = defaultdict(list)
    for row in rows:
        groups[(row.planner, row.area)].append(row)
    area_names = sorted({row.area for row in rows})
    best_volume: dict[str, float] = {}
    for (_, area_name), members in groups.items():
        mean = sum(m.result.volume_at_plateau_m3 for m in members) / len(members)
        best_volume[area_name] = max(best_volume.get(area_name, 0.0), mean)

    entries: list[LeaderboardEntry] = []
    for (planner, area_name), members in sorted(groups.items()):
        results = [m.result for m in members]
        best = best_volume[area_name]
        entries.append(LeaderboardEntry(
            planner=planner, builtin=members[0].builtin, area=area_name, runs=len(members),
            coverage=spread([r.coverage for r in results]),
            relative_coverage=spread([r.volume_at_plateau_m3 / best if best > 0 else 0.0
                                      for r in results]),
            fscore=spread([r.fscore for r in results]),
            rmse_m=spread([r.rmse_m for r in results]),
            path_length_m=spread([r.path_length_m for r in results]),
            iterations=spread([float(r.iterations) for r in results]),
            planning_ms=spread([r.planning_ms_median for r in results]),
            collisions=sum(r.collisions for r in results),
            coverage_rank=0.0, fscore_rank=None,
        ))
    for area_name in area_names:
        here = [e for e in entries if e.area == area_name]
        cov = ranks({e.planner: e.coverage.mean or 0.0 for e in here})
        fs = ranks({e.planner: e.fscore.mean for e in here if e.fscore.mean is not None})
        for e in here:
            e.coverage_rank = cov[e.planner]
            e.fscore_rank = fs.get(e.planner)
    return Leaderboard(preset=preset, areas=area_names, overall=_overall(entries),
                       entries=entries)


def _overall(entries: list[LeaderboardEntry]) -> list[LeaderboardPlanner]:
    by_planner: dict[str, list[LeaderboardEntry]] = defaultdict(list)
    for e in entries:
        by_planner[e.planner].append(e)
    overall = []
    for planner, mine in by_planner.items():
        fscores = [e.fscore.mean for e in mine if e.fscore.mean is not None]
        franks = [e.fscore_rank for e in mine if e.fscore_rank is not None]
        rmses = [e.rmse_m.mean for e in mine if e.rmse_m.mean is not None]
        overall.append(LeaderboardPlanner(
            planner=planner, builtin=mine[0].builtin, areas=len(mine),
            mean_coverage=sum(e.coverage.mean or 0.0 for e in mine) / len(mine),
            mean_relative_coverage=sum(e.relative_coverage.mean or 0.0 for e in mine) / len(mine),
            mean_fscore=sum(fscores) / len(fscores) if fscores else None,
            mean_coverage_rank=sum(e.coverage_rank for e in mine) / len(mine),
            mean_fscore_rank=sum(franks) / len(franks) if franks else None,
            rank=0,
            mean_rmse_m=sum(rmses) / len(rmses) if rmses else None,
        ))
    overall.sort(key=lambda p: (p.mean_coverage_rank, -p.mean_coverage))
    for i, p in enumerate(overall, start=1):
        p.rank = i
    _mark_pareto(overall)
    return overall


def _mark_pareto(overall: list[LeaderboardPlanner]) -> None:
    """The paper's Figure 6: the planners no other beats in both coverage and F-score rank.

    Lower ranks are better. A planner without an F-score rank (no mesh scores) is left out.
    """
    ranked = [(p, p.mean_coverage_rank, p.mean_fscore_rank) for p in overall
              if p.mean_fscore_rank is not None]
    for p, cov, fs in ranked:
        p.pareto = not any(qc <= cov and qf <= fs and (qc < cov or qf < fs)
                           for _, qc, qf in ranked)
