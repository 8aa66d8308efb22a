"""Benchmark versions: which ones have results, which one is current, which one a request means.

A result is filed under the benchmark version it was made with (`RunResult.benchmark_version`,
from the run's reproducibility record); results of different versions are never ranked together.
The current version is this service's code's: `flybo.app` hands it to the API
(`server.app.create_app(benchmark_version=...)`, as `server` may not import `flybo`). An API made
without one takes the version of the newest result as current.
"""

from __future__ import annotations

from typing import Any

from sqlalchemy import Connection, func, select
from sqlalchemy.orm import Session

from server.models import LEGACY_VERSION, Run, RunResult, RunState
from server.schemas import BenchmarkVersionOut, BenchmarkVersions


class UnknownBenchmarkVersionError(LookupError):
    """No result was made by the requested benchmark version, nor is it the current one."""

    def __init__(self, requested: str, known: list[str]) -> None:
        super().__init__(f"unknown benchmark version {requested!r}; known: "
                         f"{', '.join(known) or 'none'}")
        self.requested, self.known = requested, known


def version_counts(conn: Connection | Session, preset: str | None = None) -> list[tuple[str, int]]:
    """(version, succeeded runs) of every version with results, the newest result's first;
    in `preset` only, when given."""
    query = (select(RunResult.benchmark_version, func.count(), func.max(Run.id))
             .join(Run, RunResult.run_id == Run.id)
             .where(Run.status == RunState.SUCCEEDED.value)
             .group_by(RunResult.benchmark_version)
             .order_by(func.max(Run.id).desc()))
    if preset is not None:
        query = query.where(Run.preset == preset)
    return [(str(version), int(count)) for version, count, _ in conn.execute(query)]


def configured_version(state: Any) -> str | None:
    """The current version the app was given (`app.state.benchmark_version`), if any."""
    version = getattr(state, "benchmark_version", None)
    return version if isinstance(version, str) and version else None


def current_version(state: Any, conn: Connection | Session) -> str:
    """The app's current version; without one, the newest result's (`LEGACY_VERSION` when
    there are none)."""
    configured = configured_version(state)
    if configured is not None:
        return configured
    counts = version_counts(conn)
    return counts[0][0] if counts else LEGACY_VERSION


def known_versions(conn: Connection | Session, current: str) -> list[str]:
    """The current version and every version with results, current first."""
    return [current, *(v for v, _ in version_counts(conn) if v != current)]


def check_known(conn: Connection | Session, requested: str, current: str) -> None:
    """Raise `UnknownBenchmarkVersionError` unless `requested` is current or has results."""
    if requested == current:
        return
    known = known_versions(conn, current)
    if requested not in known:
        raise UnknownBenchmarkVersionError(requested, known)


def list_versions(conn: Connection | Session, current: str,
                  preset: str | None = None) -> BenchmarkVersions:
    """The versions with results (in `preset` only, when given) and which one is current."""
    counts = version_counts(conn, preset)
    return BenchmarkVersions(current=current, preset=preset, versions=[
        BenchmarkVersionOut(benchmark_version=v, runs=n, current=v == current)
        for v, n in counts])
