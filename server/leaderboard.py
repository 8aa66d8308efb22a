"""The leaderboard: per planner and area, mean/min/max over succeeded runs, and ranks.

A board holds the results of one benchmark version only (`server.benchmark_versions`): results
made by different code are never ranked together.

Ranks follow the paper: per area, planners are ranked by mean coverage and by mean F-score
(1 is best, ties share the mean rank); the overall table averages them over the areas a planner
ran. Relative coverage is a run's explored observable volume (the `explored_observable_m3`
metric) over the best mean of any planner on that area; a legacy result, which has no metrics,
counts its explored volume at the plateau time (`docs/metrics.md`). Besides these fixed columns
a board carries every metric the measures flag for the leaderboard (`sim.measures.metric_infos`,
`leaderboard=True`), mean/min/max per planner and area. Every mean over runs carries a
bootstrap 95 % interval; planners whose intervals cannot be told apart share a rank
(`server.board_statistics`, `docs/statistics.md`).

Every API process caches the computed boards per database and (preset, benchmark version,
area), with their JSON bodies, under the results version of the preset (with Redis, the results
epoch of `server.shared_state`). Every request checks it; concurrent requests share one check
(`_Gate`), so a busy endpoint costs one small query per batch of requests and serves bytes.
"""

from __future__ import annotations

import asyncio
import functools
import hashlib
import threading
import weakref
from collections import defaultdict
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from pydantic import TypeAdapter
from sqlalchemy import Connection, Engine, func, select
from sqlalchemy.orm import Session, sessionmaker

from server.board_statistics import INFO as STATISTICS
from server.board_statistics import Cell, annotate, describe
from server.coalesce import Coalesced
from server.db import read_only
from server.models import AreaRow, Job, PlannerRow, Run, RunResult, RunState
from server.schemas import Leaderboard, LeaderboardEntry, LeaderboardPlanner, MetricOut


@dataclass
class _Row:
    planner: str
    builtin: bool
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


Version = tuple[int, int, int]
_MAX_ENTRIES = 256  # cached boards (and gates, locks) per database before starting afresh
_ADAPTER = TypeAdapter(Leaderboard)
# The stored results' version for one preset: count and highest id of its succeeded runs, and
# the number of planners. One statement, so that a check is one round trip.
_PLANNERS = select(func.count(PlannerRow.id)).scalar_subquery()


def results_version(conn: Connection | Session, preset: str) -> Version:
    """What the cached leaderboards of `preset` are valid for (an indexed aggregate)."""
    row = conn.execute(
        select(func.count(Run.id), func.coalesce(func.max(Run.id), 0), _PLANNERS)
        .where(Run.status == RunState.SUCCEEDED.value, Run.preset == preset)).one()
    return int(row[0]), int(row[1]), int(row[2] or 0)


@dataclass(frozen=True)
class Served:
    """One computed leaderboard and its response body, exactly as FastAPI would serialize the
    `Leaderboard` response model, with a strong ETag of that body."""

    version: Version
    board: Leaderboard
    body: bytes
    etag: str

    @classmethod
    def of(cls, version: Version, board: Leaderboard) -> Served:
        body = _ADAPTER.dump_json(board, by_alias=True)
        return cls(version, board, body, '"' + hashlib.blake2b(body, digest_size=16).hexdigest()
                   + '"')


# A board's cache key: (preset, benchmark version, area).
Key = tuple[str, str, str | None]


class _Gate:
    """Exact freshness for concurrent async requests at one query per batch.

    A request needs a version check that started after it arrived (what a query of its own would
    give). Requests that arrive while a check runs wait for the next one, which starts as soon as
    that check ends and answers all of them: under load one query serves many requests.
    """

    def __init__(self) -> None:
        self.loop: asyncio.AbstractEventLoop | None = None
        self.checks: Coalesced[None, Version] = Coalesced(_no_check)
        self.computing: dict[tuple[str, str | None], asyncio.Lock] = {}

    async def version(self, check: Callable[[], Version]) -> Version:
        loop = asyncio.get_running_loop()
        if self.loop is not loop:  # a new event loop (tests): nothing carries over
            self.loop, self.computing = loop, {}
        return await self.checks.get(None, lambda _: check())


def _no_check(_: None) -> Version:
    raise AssertionError("every version check passes its own read")


class _Store:
    """The cached leaderboards of one database (one engine's pool)."""

    def __init__(self) -> None:
        self.served: dict[Key, Served] = {}
        self.gates: dict[str, _Gate] = {}
        self.reader: Engine | None = None  # for version checks: a bare connection, no session
        self.lock = threading.Lock()

    def get(self, key: Key, version: Version) -> Served | None:
        with self.lock:
            hit = self.served.get(key)
        return hit if hit is not None and hit.version == version else None

    def put(self, key: Key, served: Served) -> None:
        with self.lock:
            if len(self.served) > _MAX_ENTRIES:
                self.served.clear()
            self.served[key] = served


# Per database, so that two apps (or tests) on different databases never share an entry.
_stores: weakref.WeakKeyDictionary[Any, _Store] = weakref.WeakKeyDictionary()
_stores_lock = threading.Lock()


def _store(bind: Engine | Connection) -> _Store:
    pool = bind.engine.pool
    with _stores_lock:
        store = _stores.get(pool)
        if store is None:
            store = _stores[pool] = _Store()
        return store


def has_board(engine: Engine, preset: str, area: str | None, benchmark_version: str) -> bool:
    """Whether this process holds a board of (preset, version, area), current or not: then the
    version was known when it was computed (results are never deleted)."""
    store = _store(engine)
    with store.lock:
        return (preset, benchmark_version, area) in store.served


def build_leaderboard(session: Session, preset: str, area: str | None = None, *,
                      benchmark_version: str) -> Leaderboard:
    """The leaderboard of `benchmark_version`'s results, recomputed only when the stored
    results changed (a copy to keep).

    The check is one indexed aggregate (count and highest id of finished runs, number of
    planners), so polling clients cost little; every API process keeps its own copy.
    """
    return _served(session, preset, area, benchmark_version).board.model_copy(deep=True)


def _served(session: Session, preset: str, area: str | None, benchmark_version: str) -> Served:
    store = _store(session.get_bind())
    version = results_version(session, preset)
    key = (preset, benchmark_version, area)
    hit = store.get(key, version)
    if hit is not None:
        return hit
    served = Served.of(version, compute_leaderboard(session, preset, area,
                                                    benchmark_version=benchmark_version))
    store.put(key, served)
    return served


async def serve_leaderboard(engine: Engine, sessions: sessionmaker[Session], preset: str,
                            area: str | None = None, *, benchmark_version: str,
                            epoch: Callable[[], int | None] | None = None) -> Served:
    """The current leaderboard of `benchmark_version` and its body, for the API (`engine`
    names the database, `sessions` read it). The version check is shared by the requests
    waiting for it (see `_Gate`), and a stale board is recomputed once, in a thread, however
    many requests ask for it meanwhile."""
    store = _store(engine)
    key = (preset, benchmark_version, area)
    with store.lock:
        gate = store.gates.get(preset)
        if gate is None:
            if len(store.gates) > _MAX_ENTRIES:  # presets are free text: do not grow unbounded
                store.gates.clear()  # a gate still in use finishes its checks on its own
            gate = store.gates[preset] = _Gate()
        if store.reader is None:
            store.reader = read_only(engine)
        reader = store.reader

    def check() -> Version:
        # With Redis, the shared results epoch (server.shared_state) instead of the aggregate.
        if epoch is not None and (current := epoch()) is not None:
            return current, -1, -1
        with reader.connect() as conn:
            return results_version(conn, preset)

    version = await gate.version(check)
    hit = store.get(key, version)
    if hit is not None:
        return hit
    lock = gate.computing.get((benchmark_version, area))
    if lock is None:
        if len(gate.computing) > _MAX_ENTRIES:
            gate.computing.clear()
        lock = gate.computing[(benchmark_version, area)] = asyncio.Lock()
    async with lock:
        hit = store.get(key, version)
        if hit is not None:
            return hit

        def compute() -> Served:
            with sessions() as session:
                served = Served.of(version, compute_leaderboard(
                    session, preset, area, benchmark_version=benchmark_version))
            store.put(key, served)
            return served

        return await asyncio.to_thread(compute)


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
                        benchmark_version: str) -> Leaderboard:
    query = (
        select(PlannerRow.name, PlannerRow.version, PlannerRow.builtin, AreaRow.name, RunResult)
        .join(Run, RunResult.run_id == Run.id)
        .join(Job, Run.job_id == Job.id)
        .join(PlannerRow, Job.planner_id == PlannerRow.id)
        .join(AreaRow, Run.area_id == AreaRow.id)
        .where(Run.status == RunState.SUCCEEDED.value, Run.preset == preset,
               RunResult.benchmark_version == benchmark_version)
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
            planner=planner, builtin=members[0].builtin, area=area_name, runs=len(members),
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
    return Leaderboard(preset=preset, benchmark_version=benchmark_version,
                       metrics=metrics, areas=area_names, overall=overall, entries=entries,
                       statistics=STATISTICS)


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
            planner=planner, builtin=mine[0].builtin, areas=len(mine),
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
