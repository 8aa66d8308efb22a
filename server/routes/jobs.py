"""Jobs: a planner on some areas, several seeded runs each.

`GET /jobs/{id}` is what clients poll: it is read with one Core query (`server.jobs.read_job`),
shared by the concurrent polls of the same job (`server.coalesce`), and carries a strong ETag
(a hash of the body), so that a client sending it back in If-None-Match gets 304 without a
body while nothing changed, and `Retry-After` as a polling hint while the job is queued or
running.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from typing import Annotated, Any

from fastapi import APIRouter, Header, HTTPException, Query, Request, Response
from sqlalchemy import Engine, func, select
from sqlalchemy.orm import selectinload

from server.coalesce import Coalesced
from server.deps import IdPath, SessionDep, SettingsDep, UserDep
from server.jobs import cancel_job, create_job, job_out, may_manage, read_job, rerun_job
from server.models import AreaRow, Job, PlannerRow, Run, RunState, User
from server.routes.leaderboard import CACHE_CONTROL, etag_matches
from server.schemas import ErrorBody, JobCreate, JobOut, Page
from server.submit import submit

router = APIRouter(prefix="/jobs", tags=["jobs"])

_ERRORS: dict[int | str, dict[str, Any]] = {
    401: {"model": ErrorBody}, 403: {"model": ErrorBody}, 404: {"model": ErrorBody}}
# Seconds a poller should wait before asking again about a job that is not final: the worker
# reports progress about this often, and the job page polls at this pace.
POLL_AFTER_S = 2


def _load(session: SessionDep, job_id: int) -> Job:
    job = session.scalar(
        select(Job).where(Job.id == job_id).options(
            selectinload(Job.runs).selectinload(Run.area), selectinload(Job.planner),
            selectinload(Job.user))
    )
    if job is None:
        raise HTTPException(404, f"no job with id {job_id}")
    return job


@router.post("", status_code=201, response_model=JobOut,
             responses={**_ERRORS, 409: {"model": ErrorBody}, 422: {"model": ErrorBody},
                        429: {"model": ErrorBody}})
def submit_job(
    body: JobCreate,
    session: SessionDep,
    settings: SettingsDep,
    user: UserDep,
    response: Response,
    idempotency_key: Annotated[str | None, Header(max_length=128)] = None,
) -> JobOut:
    created = submit(session, settings, lambda: create_job(
        session, settings, user, body, idempotency_key=idempotency_key),
        idempotency_key=idempotency_key, response=response)
    return job_out(_load(session, created.job.id))


@router.get("", response_model=Page[JobOut])
def list_jobs(
    session: SessionDep,
    limit: Annotated[int, Query(ge=1, le=200)] = 50,
    offset: Annotated[int, Query(ge=0, le=2**31 - 1)] = 0,
    planner: Annotated[str | None, Query(max_length=80)] = None,
    owner: Annotated[str | None, Query(max_length=64)] = None,
    area: Annotated[str | None, Query(max_length=40)] = None,
) -> Page[JobOut]:
    query = select(Job.id)
    if planner is not None:
        query = query.join(PlannerRow, Job.planner_id == PlannerRow.id).where(
            PlannerRow.name == planner)
    if owner is not None:
        query = query.join(User, Job.user_id == User.id).where(User.name == owner)
    if area is not None:
        query = query.where(Job.id.in_(
            select(Run.job_id).join(AreaRow, Run.area_id == AreaRow.id)
            .where(AreaRow.name == area)))
    total = session.scalar(select(func.count()).select_from(query.subquery())) or 0
    ids = list(session.scalars(query.order_by(Job.id.desc()).limit(limit).offset(offset)))
    jobs = session.scalars(
        select(Job).where(Job.id.in_(ids)).order_by(Job.id.desc()).options(
            selectinload(Job.runs).selectinload(Run.area), selectinload(Job.planner),
            selectinload(Job.user))
    ).all()
    return Page[JobOut](items=[job_out(j) for j in jobs], total=total, limit=limit,
                        offset=offset)


def job_etag(body: bytes) -> str:
    """A strong ETag: equal exactly when the bodies are byte for byte equal."""
    return '"' + hashlib.sha256(body).hexdigest()[:32] + '"'


@dataclass(frozen=True)
class PolledJob:
    """`GET /jobs/{id}`'s answer: the body, its ETag, and whether the job is final."""

    body: bytes
    etag: str
    final: bool


def job_reader(engine: Engine) -> Coalesced[int, PolledJob | None]:
    """The polled answers of an app, read on `engine` (a read-only one), one query per batch
    of concurrent requests for the same job (`server.coalesce`)."""

    def read(job_id: int) -> PolledJob | None:
        with engine.connect() as conn:
            job = read_job(conn, job_id)
        if job is None:
            return None
        # Serialized as FastAPI would for `response_model=JobOut`, so the bytes hashed are
        # the bytes sent.
        body = job.model_dump_json().encode()
        return PolledJob(body, job_etag(body), RunState(job.status).final)

    return Coalesced(read)


@router.get("/{job_id}", response_model=JobOut,
            responses={**_ERRORS,
                       304: {"description": "unchanged since the ETag sent in If-None-Match"}})
async def get_job(
    request: Request,
    job_id: IdPath,
    if_none_match: Annotated[str | None, Header(max_length=1024)] = None,
) -> Response:
    # Async, without a session of its own: concurrent polls of one job share one read.
    job: PolledJob | None = await request.app.state.job_reads.get(job_id)
    if job is None:
        raise HTTPException(404, f"no job with id {job_id}")
    headers = {"ETag": job.etag, "Cache-Control": CACHE_CONTROL}
    if not job.final:
        headers["Retry-After"] = str(POLL_AFTER_S)
    if etag_matches(if_none_match, job.etag):
        return Response(status_code=304, headers=headers)
    return Response(job.body, media_type="application/json", headers=headers)


@router.post("/{job_id}/cancel", response_model=JobOut,
             responses={**_ERRORS, 409: {"model": ErrorBody}})
def cancel(job_id: IdPath, session: SessionDep, user: UserDep) -> JobOut:
    job = _load(session, job_id)
    if not may_manage(user, job):
        raise HTTPException(403, "only the job's owner or an admin may cancel it")
    cancel_job(session, job)
    session.commit()
    return job_out(_load(session, job_id))


@router.post("/{job_id}/rerun", status_code=201, response_model=JobOut,
             responses={**_ERRORS, 429: {"model": ErrorBody}})
def rerun(job_id: IdPath, session: SessionDep, settings: SettingsDep,
          user: UserDep) -> JobOut:
    job = _load(session, job_id)
    if not may_manage(user, job):
        raise HTTPException(403, "only the job's owner or an admin may re-run it")
    created = submit(session, settings, lambda: rerun_job(session, settings, user, job))
    return job_out(_load(session, created.job.id))
