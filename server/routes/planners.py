"""Planners: built-in ones and, later, uploaded ones, each with its versions."""

from __future__ import annotations

from fastapi import APIRouter, HTTPException
from sqlalchemy import select

from server.catalog import CatalogError, find_planner
from server.deps import SessionDep
from server.models import PlannerRow, User
from server.schemas import PlannerOut

router = APIRouter(prefix="/planners", tags=["planners"])


def planner_out(row: PlannerRow, owner: str | None) -> PlannerOut:
    return PlannerOut(name=row.name, version=row.version, id=row.key, builtin=row.builtin,
                      description=row.description, reference=row.reference, config=row.config,
                      owner=owner)


@router.get("", response_model=list[PlannerOut])
def list_planners(session: SessionDep) -> list[PlannerOut]:
    rows = session.execute(
        select(PlannerRow, User.name).outerjoin(User, PlannerRow.owner_id == User.id)
        .order_by(PlannerRow.name, PlannerRow.version)
    )
    return [planner_out(row, owner) for row, owner in rows]


@router.get("/{name}", response_model=PlannerOut,
            responses={404: {"description": "no such planner"}})
def get_planner(name: str, session: SessionDep) -> PlannerOut:
    try:
        row = find_planner(session, name)
    except CatalogError as exc:
        raise HTTPException(404, str(exc)) from None
    owner = session.get(User, row.owner_id) if row.owner_id is not None else None
    return planner_out(row, owner.name if owner else None)
