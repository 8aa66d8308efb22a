"""The leaderboards, computed from the stored results (`server.leaderboard_compute`, where the
ranks are described) and cached.

A board holds the results of one benchmark version only (`server.benchmark_versions`): results
made by different code are never ranked together; and the areas of one split only (the public
areas, or the held-out areas of one generation: `server.heldout`).

Every API process caches the computed boards per database and (preset, benchmark version,
area, split), with their JSON bodies, under the results version of the preset (with Redis, the
results epoch of `server.shared_state`). Every request checks it; concurrent requests share one
check (`_Gate`), so a busy endpoint costs one small query per batch of requests and serves
bytes.
"""

from __future__ import annotations

import asyncio
import hashlib
import threading
import weakref
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from pydantic import TypeAdapter
from sqlalchemy import Connection, Engine, func, select
from sqlalchemy.orm import Session, sessionmaker

from server.coalesce import Coalesced
from server.db import read_only
from server.leaderboard_compute import (
    PUBLIC_SCOPE,
    Scope,
    compute_leaderboard,
    leaderboard_metrics,
    metric_value,
    ranks,
)
from server.models import PlannerRow, Run, RunState
from server.schemas import Leaderboard

__all__ = ["PUBLIC_SCOPE", "Scope", "build_leaderboard", "compute_leaderboard",
           "leaderboard_metrics", "metric_value", "ranks", "serve_leaderboard"]

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


# A board's cache key: (preset, benchmark version, area, scope).
Key = tuple[str, str, str | None, Scope]


class _Gate:
    """Exact freshness for concurrent async requests at one query per batch.

    A request needs a version check that started after it arrived (what a query of its own would
    give). Requests that arrive while a check runs wait for the next one, which starts as soon as
    that check ends and answers all of them: under load one query serves many requests.
    """

    def __init__(self) -> None:
        self.loop: asyncio.AbstractEventLoop | None = None
        self.checks: Coalesced[None, Version] = Coalesced(_no_check)
        self.computing: dict[tuple[str, str | None, Scope], asyncio.Lock] = {}

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


def has_board(engine: Engine, preset: str, area: str | None, benchmark_version: str,
              scope: Scope = PUBLIC_SCOPE) -> bool:
    """Whether this process holds a board of (preset, version, area, scope), current or not:
    then the version was known when it was computed (results are never deleted)."""
    store = _store(engine)
    with store.lock:
        return (preset, benchmark_version, area, scope) in store.served


def build_leaderboard(session: Session, preset: str, area: str | None = None, *,
                      benchmark_version: str, scope: Scope = PUBLIC_SCOPE) -> Leaderboard:
    """The leaderboard of `benchmark_version`'s results, recomputed only when the stored
    results changed (a copy to keep).

    The check is one indexed aggregate (count and highest id of finished runs, number of
    planners), so polling clients cost little; every API process keeps its own copy.
    """
    return _served(session, preset, area, benchmark_version, scope).board.model_copy(deep=True)


def _served(session: Session, preset: str, area: str | None, benchmark_version: str,
            scope: Scope) -> Served:
    store = _store(session.get_bind())
    version = results_version(session, preset)
    key = (preset, benchmark_version, area, scope)
    hit = store.get(key, version)
    if hit is not None:
        return hit
    served = Served.of(version, compute_leaderboard(session, preset, area, scope=scope,
                                                    benchmark_version=benchmark_version))
    store.put(key, served)
    return served


async def serve_leaderboard(engine: Engine, sessions: sessionmaker[Session], preset: str,
                            area: str | None = None, *, benchmark_version: str,
                            epoch: Callable[[], int | None] | None = None,
                            scope: Scope = PUBLIC_SCOPE) -> Served:
    """The current leaderboard of `benchmark_version` and its body, for the API (`engine`
    names the database, `sessions` read it). The version check is shared by the requests
    waiting for it (see `_Gate`), and a stale board is recomputed once, in a thread, however
    many requests ask for it meanwhile."""
    store = _store(engine)
    key = (preset, benchmark_version, area, scope)
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
    lock = gate.computing.get((benchmark_version, area, scope))
    if lock is None:
        if len(gate.computing) > _MAX_ENTRIES:
            gate.computing.clear()
        lock = gate.computing[(benchmark_version, area, scope)] = asyncio.Lock()
    async with lock:
        hit = store.get(key, version)
        if hit is not None:
            return hit

        def compute() -> Served:
            with sessions() as session:
                served = Served.of(version, compute_leaderboard(
                    session, preset, area, benchmark_version=benchmark_version, scope=scope))
            store.put(key, served)
            return served

        return await asyncio.to_thread(compute)


