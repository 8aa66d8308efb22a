"""The leaderboard, computed from the stored results.

Served from the process's cache as stored JSON bytes (see `server.leaderboard`), with a strong
ETag: a client that sends it back in If-None-Match gets 304 without a body while the results
are unchanged.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query, Request, Response
from sqlalchemy.orm import Session, sessionmaker

from server.leaderboard import serve_leaderboard
from server.schemas import Leaderboard

router = APIRouter(tags=["leaderboard"])
# Clients may keep a copy but must revalidate it (cheap: a 304) before using it.
CACHE_CONTROL = "no-cache"


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


@router.get("/leaderboard", response_model=Leaderboard,
            responses={304: {"description": "unchanged since the ETag sent in If-None-Match"}})
async def leaderboard(
    request: Request,
    preset: Annotated[str, Query(max_length=32)] = "default",
    area: Annotated[str | None, Query(max_length=40)] = None,
) -> Response:
    # An async endpoint without a session dependency: a cached answer needs no worker thread
    # and no pooled connection of its own (the version check is shared, see serve_leaderboard).
    state = request.app.state
    sessions: sessionmaker[Session] = getattr(state, "read_sessions", state.sessions)
    served = await serve_leaderboard(state.engine, sessions, preset, area)
    headers = {"ETag": served.etag, "Cache-Control": CACHE_CONTROL}
    if etag_matches(request.headers.get("if-none-match"), served.etag):
        return Response(status_code=304, headers=headers)
    return Response(served.body, media_type="application/json", headers=headers)
