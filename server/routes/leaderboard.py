"""The leaderboard, computed from the stored results."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query

from server.deps import SessionDep
from server.leaderboard import build_leaderboard
from server.schemas import Leaderboard

router = APIRouter(tags=["leaderboard"])


@router.get("/leaderboard", response_model=Leaderboard)
def leaderboard(
    session: SessionDep,
    preset: Annotated[str, Query(max_length=32)] = "default",
    area: Annotated[str | None, Query(max_length=40)] = None,
) -> Leaderboard:
    return build_leaderboard(session, preset, area)
