"""The leaderboard of one benchmark version, computed from the stored results, and the list of
the benchmark versions that have results.

Served from the process's cache as stored JSON bytes (see `server.leaderboard`), with a strong
ETag: a client that sends it back in If-None-Match gets 304 without a body while the results
are unchanged. A client that accepts gzip (browsers, httpx, requests do by default) gets the
body compressed once per board: a sixth of the bytes to write for every answer.
"""

from __future__ import annotations

import asyncio
import gzip
from typing import Annotated, Any, Literal

from fastapi import APIRouter, HTTPException, Query, Request, Response
from sqlalchemy.orm import Session, sessionmaker

from server.benchmark_versions import (
    UnknownBenchmarkVersionError,
    check_known,
    configured_version,
    current_version,
    list_versions,
)
from server.deps import SessionDep
from server.heldout import current_generation
from server.leaderboard import PUBLIC_SCOPE, Scope, Served, has_board, serve_leaderboard
from server.models import HELDOUT_SPLIT, PUBLIC_SPLIT
from server.schemas import BenchmarkVersions, ErrorBody, Leaderboard

router = APIRouter(tags=["leaderboard"])
# Clients may keep a copy but must revalidate it (cheap: a 304) before using it.
CACHE_CONTROL = "no-cache"
VERSION_QUERY = Query(max_length=64, description="the benchmark version whose results are "
                      "ranked (`/benchmark-versions` lists them); default: the current one")


def etag_matches(if_none_match: str | None, etag: str) -> bool:
    """Whether If-None-Match names `etag` (weak comparison, as RFC 9110 asks for GET)."""
    if not if_none_match:
        return False
    wanted = etag.removeprefix("W/")
    for candidate in if_none_match.split(","):
        candidate = candidate.strip()
        if candidate == "*" or candidate.removeprefix("W/") == wanted:
            return True
    return False


def _in_thread_session(sessions: sessionmaker[Session], fn: Any, *args: Any) -> Any:
    """`fn(*args, session)` with a session of its own (for a worker thread)."""
    with sessions() as session:
        return fn(*args, session)


@router.get("/leaderboard", response_model=Leaderboard,
            responses={304: {"description": "unchanged since the ETag sent in If-None-Match"},
                       404: {"model": ErrorBody, "description": "unknown benchmark version"}})
async def leaderboard(
    request: Request,
    preset: Annotated[str, Query(max_length=32)] = "default",
    area: Annotated[str | None, Query(max_length=40)] = None,
    benchmark_version: Annotated[str | None, VERSION_QUERY] = None,
    split: Annotated[Literal["public", "heldout"], Query(
        description="'public': the public areas; 'heldout': the held-out areas of one "
                    "generation, shown by their opaque names only")] = "public",
    heldout_generation: Annotated[int | None, Query(
        ge=1, le=2**31 - 1, description="the held-out generation ranked (with "
        "split=heldout); default: the current one")] = None,
) -> Response:
    """The results of one benchmark version and one split, never mixed with another's."""
    # An async endpoint without a session dependency: a cached answer needs no worker thread
    # and no pooled connection of its own (the version check is shared, see serve_leaderboard).
    state = request.app.state
    sessions: sessionmaker[Session] = getattr(state, "read_sessions", state.sessions)
    current = configured_version(state)
    if current is None:  # an API made without its version: the newest result's
        current = str(await asyncio.to_thread(_in_thread_session, sessions, current_version,
                                              state))
    version = benchmark_version or current
    if version != current and not has_board(state.engine, preset, area, version):
        # Another version, not asked for before: is it one? (One query, and no board is
        # computed and cached for a version nobody knows.)
        try:
            await asyncio.to_thread(_in_thread_session, sessions, _check, version, current)
        except UnknownBenchmarkVersionError as exc:
            raise HTTPException(404, str(exc)) from None
    scope = await _scope(sessions, split, heldout_generation)
    served = await serve_leaderboard(state.engine, sessions, preset, area,
                                     benchmark_version=version, scope=scope,
                                     epoch=getattr(state, "results_epoch", None))
    zipped = accepts_gzip(request.headers.get("accept-encoding"))
    # Each encoding is a representation of its own, with a strong ETag of its own.
    etag = gzip_etag(served.etag) if zipped else served.etag
    headers = {"ETag": etag, "Cache-Control": CACHE_CONTROL, "Vary": "Accept-Encoding"}
    if etag_matches(request.headers.get("if-none-match"), etag):
        return Response(status_code=304, headers=headers)
    if zipped:
        headers["Content-Encoding"] = "gzip"
        return Response(gzipped(served), media_type="application/json", headers=headers)
    return Response(served.body, media_type="application/json", headers=headers)


async def _scope(sessions: sessionmaker[Session], split: str,
                 generation: int | None) -> Scope:
    """The board's scope; 404 for a held-out generation that was never started."""
    if split == PUBLIC_SPLIT:
        if generation is not None:
            raise HTTPException(422, "heldout_generation goes with split=heldout only")
        return PUBLIC_SCOPE
    current = int(await asyncio.to_thread(_in_thread_session, sessions, current_generation))
    if generation is None:
        return HELDOUT_SPLIT, current
    if generation > current:
        raise HTTPException(404, f"unknown held-out generation {generation}; the current one "
                                 f"is {current}")
    return HELDOUT_SPLIT, generation


def accepts_gzip(accept_encoding: str | None) -> bool:
    """Whether Accept-Encoding allows gzip (not refused with q=0)."""
    for item in (accept_encoding or "").split(","):
        coding, _, params = item.strip().partition(";")
        if coding.strip().lower() in ("gzip", "x-gzip", "*"):
            return params.replace(" ", "").lower() not in ("q=0", "q=0.0", "q=0.00", "q=0.000")
    return False


def gzip_etag(etag: str) -> str:
    return etag[:-1] + '-gz"'


_GZIPPED: dict[str, bytes] = {}


def gzipped(served: Served) -> bytes:
    """The board's body compressed, once per board (by its ETag, a hash of the body)."""
    body = _GZIPPED.get(served.etag)
    if body is None:
        if len(_GZIPPED) > 64:
            _GZIPPED.clear()
        body = _GZIPPED[served.etag] = gzip.compress(served.body, compresslevel=6, mtime=0)
    return body


def _check(version: str, current: str, session: Session) -> None:
    check_known(session, version, current)


@router.get("/benchmark-versions", response_model=BenchmarkVersions)
def benchmark_versions(
    request: Request, session: SessionDep,
    preset: Annotated[str | None, Query(max_length=32, description="count the results of this "
                                        "preset only")] = None,
) -> BenchmarkVersions:
    """The benchmark versions that have results, with their counts, and the current one (the
    leaderboard's default)."""
    return list_versions(session, current_version(request.app.state, session), preset)
