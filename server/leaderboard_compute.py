"""Computing one leaderboard from the stored results (see `server.leaderboard`, which caches
and serves them): per planner and area, mean/min/max over succeeded runs, and ranks.

A board ranks the areas of one split (`server.models.PUBLIC_SPLIT`, or the held-out areas of one
generation, `server.heldout`) and the results of one benchmark version.
"""

from __future__ import annotations

import functools
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from sqlalchemy.orm import Session

from server.board_statistics import INFO as STATISTICS
from server.board_statistics import Cell, annotate, describe
from server.models import PUBLIC_SPLIT, AreaRow, PlannerRow, RunResult
from server.result_queries import succeeded_results
from server.schemas import Leaderboard, LeaderboardEntry, LeaderboardPlanner, MetricOut

# Which areas a board ranks: (split, held-out generation); the public board has no generation.
Scope = tuple[str, int | None]
PUBLIC_SCOPE: Scope = (PUBLIC_SPLIT, None)


@dataclass
class _Row:
    planner: str
    builtin: bool
    method: str
    area: str
    result: RunResult


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


@functools.cache
def _leaderboard_infos() -> tuple[dict[str, Any], ...]:
    from sim.measures import metric_infos  # the simulation stack, on use (see server.catalog)

    return tuple({"key": m.key, "label": m.label, "unit": m.unit,
                  "higher_is_better": m.higher_is_better, "fmt": m.fmt}
                 for m in metric_infos() if m.leaderboard)


def leaderboard_metrics() -> list[MetricOut]:
    """The metrics the measures flag for the leaderboard, in registry order."""
    return [MetricOut(**info) for info in _leaderboard_infos()]


def metric_value(result: RunResult, key: str) -> float | None:
    """A result's metric `key`: from its metrics block, or, for a legacy result (no block),
    the column of that name if it has one."""
    if result.metrics is not None:
        value = result.metrics.get(key)
    else:
        value = getattr(result, key, None) if key in RunResult.__table__.columns else None
    return float(value) if isinstance(value, int | float) and not isinstance(value, bool) \
        else None


def _explored(result: RunResult) -> float:
    """What relative coverage compares: the explored observable volume, or a legacy result's
    explored volume at the plateau time."""
    observable = metric_value(result, "explored_observable_m3")
    return observable if observable is not None else result.volume_at_plateau_m3


_METRIC = "metric:"  # a measures' metric among a cell's columns (`describe`)


def _mean(values: Sequence[float | None]) -> float | None:
    finite = [v for v in values if v is not None]
    return sum(finite) / len(finite) if finite else None


def compute_leaderboard(session: Session, preset: str, area: str | None = None, *,
                        benchmark_version: str, scope: Scope = PUBLIC_SCOPE) -> Leaderboard:
    split, generation = scope
    query = succeeded_results(
        PlannerRow.name, PlannerRow.version, PlannerRow.builtin, PlannerRow.method,
        AreaRow.name, RunResult,
        preset=preset, benchmark_version=benchmark_version).where(AreaRow.split == split)
    if split != PUBLIC_SPLIT:  # one generation only: never ranked with another's areas
        query = query.where(AreaRow.heldout_generation == generation)
    if area is not None:
        query = query.where(AreaRow.name == area)
    rows = [_Row(f"{name}-v{version}", builtin, method, area_name, result)
            for name, version, builtin, method, area_name, result in session.execute(query)]
    groups: dict[tuple[str, str], list[_Row]] = defaultdict(list)
    for row in rows:
        groups[(row.planner, row.area)].append(row)
    area_names = sorted({row.area for row in rows})
    best_volume: dict[str, float] = {}
    for (_, area_name), members in groups.items():
        mean = sum(_explored(m.result) for m in members) / len(members)
        best_volume[area_name] = max(best_volume.get(area_name, 0.0), mean)
    metrics = leaderboard_metrics()

    entries: list[LeaderboardEntry] = []
    cells: dict[tuple[str, str], Cell] = {}
    for (planner, area_name), members in sorted(groups.items()):
        results = [m.result for m in members]
        best = best_volume[area_name]
        spreads, cells[(planner, area_name)] = describe(planner, area_name, {
            "coverage": [r.coverage for r in results],
            "relative_coverage": [_explored(r) / best if best > 0 else 0.0 for r in results],
            "fscore": [r.fscore for r in results], "rmse_m": [r.rmse_m for r in results],
            "path_length_m": [r.path_length_m for r in results],
            "iterations": [float(r.iterations) for r in results],
            "planning_ms": [r.planning_ms_median for r in results],
            **{_METRIC + m.key: [metric_value(r, m.key) for r in results] for m in metrics}})
        entries.append(LeaderboardEntry(
            planner=planner, builtin=members[0].builtin, method=members[0].method,
            area=area_name, runs=len(members),
            coverage=spreads["coverage"], relative_coverage=spreads["relative_coverage"],
            fscore=spreads["fscore"], rmse_m=spreads["rmse_m"],
            path_length_m=spreads["path_length_m"], iterations=spreads["iterations"],
            planning_ms=spreads["planning_ms"], collisions=sum(r.collisions for r in results),
            coverage_rank=0.0, fscore_rank=None,
            metrics={m.key: spreads[_METRIC + m.key] for m in metrics}))
    for area_name in area_names:
        here = [e for e in entries if e.area == area_name]
        cov = ranks({e.planner: e.coverage.mean or 0.0 for e in here})
        fs = ranks({e.planner: e.fscore.mean for e in here if e.fscore.mean is not None})
        for e in here:
            e.coverage_rank = cov[e.planner]
            e.fscore_rank = fs.get(e.planner)
    overall = _overall(entries, metrics)
    annotate(entries, overall, cells)
    if split != PUBLIC_SPLIT:
        _add_public_gaps(session, overall, preset, benchmark_version)
    return Leaderboard(preset=preset, split=split, heldout_generation=generation,
                       benchmark_version=benchmark_version,
                       metrics=metrics, areas=area_names, overall=overall, entries=entries,
                       statistics=STATISTICS)


def _add_public_gaps(session: Session, overall: list[LeaderboardPlanner], preset: str,
                     benchmark_version: str) -> None:
    """Each held-out planner's public mean coverage and the gap to it (the overfitting signal).
    A board of one held-out area is compared with the whole public board: its family is
    secret."""
    public = compute_leaderboard(session, preset, benchmark_version=benchmark_version)
    scores = {p.planner: p.mean_coverage for p in public.overall}
    for p in overall:
        mine = scores.get(p.planner)
        p.public_mean_coverage = mine
        p.public_gap = None if mine is None else mine - p.mean_coverage


def _overall(entries: list[LeaderboardEntry],
             metrics: Sequence[MetricOut]) -> list[LeaderboardPlanner]:
    by_planner: dict[str, list[LeaderboardEntry]] = defaultdict(list)
    for e in entries:
        by_planner[e.planner].append(e)
    overall = []
    for planner, mine in by_planner.items():
        fscores = [e.fscore.mean for e in mine if e.fscore.mean is not None]
        franks = [e.fscore_rank for e in mine if e.fscore_rank is not None]
        rmses = [e.rmse_m.mean for e in mine if e.rmse_m.mean is not None]
        overall.append(LeaderboardPlanner(
            planner=planner, builtin=mine[0].builtin, method=mine[0].method, areas=len(mine),
            mean_coverage=sum(e.coverage.mean or 0.0 for e in mine) / len(mine),
            mean_relative_coverage=sum(e.relative_coverage.mean or 0.0 for e in mine) / len(mine),
            mean_fscore=sum(fscores) / len(fscores) if fscores else None,
            mean_coverage_rank=sum(e.coverage_rank for e in mine) / len(mine),
            mean_fscore_rank=sum(franks) / len(franks) if franks else None,
            rank=0,
            mean_rmse_m=sum(rmses) / len(rmses) if rmses else None,
            mean_metrics={m.key: _mean([e.metrics[m.key].mean for e in mine]) for m in metrics},
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
