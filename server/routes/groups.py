"""Job groups: a suite of planners x areas x runs submitted at once, followed as one."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Header, HTTPException, Query, Request, Response
from sqlalchemy import func, select
from sqlalchemy.orm import Session, selectinload

from server.benchmark_versions import current_version
from server.deps import IdPath, SessionDep, SettingsDep, UserDep
from server.groups import GroupCreate, GroupOut, cancel_group, create_group, group_out
from server.models import Job, JobGroup, Run, User
from server.schemas import ErrorBody, Page
from server.submit import submit

router = APIRouter(prefix="/groups", tags=["groups"])

_ERRORS: dict[int | str, dict[str, Any]] = {
    401: {"model": ErrorBody}, 403: {"model": ErrorBody}, 404: {"model": ErrorBody}}


def _options() -> Any:
    return selectinload(JobGroup.jobs).options(
        selectinload(Job.runs).selectinload(Run.area), selectinload(Job.planner))


def _load(session: Session, group_id: int) -> JobGroup:
    group = session.scalar(select(JobGroup).where(JobGroup.id == group_id).options(
        _options(), selectinload(JobGroup.user)))
    if group is None:
        raise HTTPException(404, f"no job group with id {group_id}")
    return group


@router.post("", status_code=201, response_model=GroupOut,
             responses={**_ERRORS, 409: {"model": ErrorBody}, 422: {"model": ErrorBody},
                        429: {"model": ErrorBody}})
def submit_group(
    body: GroupCreate,
    session: SessionDep,
    settings: SettingsDep,
    user: UserDep,
    response: Response,
    request: Request,
    idempotency_key: Annotated[str | None, Header(max_length=128)] = None,
) -> GroupOut:
    """One job per planner (every area, `runs` seeds each), stored in one transaction; with
    `heldout`, the areas' held-out counterparts too."""
    version = current_version(request.app.state, session)
    created = submit(session, settings, lambda: create_group(
        session, settings, user, body, idempotency_key=idempotency_key,
        benchmark_version=version),
        idempotency_key=idempotency_key, response=response)
    return group_out(_load(session, created.group.id))


@router.get("", response_model=Page[GroupOut])
def list_groups(
    session: SessionDep,
    limit: Annotated[int, Query(ge=1, le=200)] = 50,
    offset: Annotated[int, Query(ge=0, le=2**31 - 1)] = 0,
    owner: Annotated[str | None, Query(max_length=64)] = None,
) -> Page[GroupOut]:
    query = select(JobGroup.id)
    if owner is not None:
        query = query.join(User, JobGroup.user_id == User.id).where(User.name == owner)
    total = session.scalar(select(func.count()).select_from(query.subquery())) or 0
    ids = list(session.scalars(query.order_by(JobGroup.id.desc()).limit(limit).offset(offset)))
    groups = session.scalars(select(JobGroup).where(JobGroup.id.in_(ids))
                             .order_by(JobGroup.id.desc())
                             .options(_options(), selectinload(JobGroup.user))).all()
    return Page[GroupOut](items=[group_out(g) for g in groups], total=total, limit=limit,
                          offset=offset)


@router.get("/{group_id}", response_model=GroupOut, responses=_ERRORS)
def get_group(group_id: IdPath, session: SessionDep) -> GroupOut:
    """Progress: runs by status, over the group and per planner."""
    return group_out(_load(session, group_id))


@router.post("/{group_id}/cancel", response_model=GroupOut, responses=_ERRORS)
def cancel(group_id: IdPath, session: SessionDep, user: UserDep) -> GroupOut:
    """Queued runs end cancelled now; running ones are asked to stop."""
    group = _load(session, group_id)
    if not (user.is_admin or group.user_id == user.id):
        raise HTTPException(403, "only the group's owner or an admin may cancel it")
    cancel_group(session, group)
    session.commit()
    return group_out(_load(session, group_id))
