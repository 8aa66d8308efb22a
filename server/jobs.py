"""Creating, cancelling and re-running jobs, with quotas and idempotency.

Every function works inside the caller's session; the caller commits and only then enqueues the
returned run ids, so a worker never sees a run that is not stored yet.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import timedelta

from sqlalchemy import Connection, and_, bindparam, exists, func, select
from sqlalchemy.orm import Session

from server.catalog import CatalogError, ensure_area, find_planner, preset_names
from server.heldout import current_generation
from server.models import (
    ACTIVE_STATES,
    HELDOUT_SPLIT,
    AreaRow,
    FailureKind,
    Job,
    PlannerRow,
    Run,
    RunState,
    User,
    utcnow,
)
from server.schemas import JobCreate, JobOut, RunBrief
from server.settings import Settings


class JobError(ValueError):
    """The request cannot be served; `status` is the HTTP status to answer with."""

    def __init__(self, status: int, message: str) -> None:
        super().__init__(message)
        self.status = status


@dataclass(frozen=True)
class Created:
    job: Job
    runs: list[tuple[int, float]]  # (run id, simulated seconds) to enqueue
    replayed: bool


def request_hash(body: JobCreate) -> str:
    canonical = json.dumps(body.model_dump(mode="json"), sort_keys=True)
    return hashlib.sha256(canonical.encode()).hexdigest()


def create_job(session: Session, settings: Settings, user: User, body: JobCreate, *,
               idempotency_key: str | None = None, rerun_of: int | None = None,
               group_id: int | None = None) -> Created:
    digest = request_hash(body)
    if idempotency_key is not None:
        previous = session.scalar(select(Job).where(Job.user_id == user.id,
                                                    Job.idempotency_key == idempotency_key))
        if previous is not None:
            if previous.request_hash != digest:
                raise JobError(409, "this Idempotency-Key was used for a different request")
            return Created(previous, [], replayed=True)
    try:
        planner = find_planner(session, body.planner)
    except CatalogError as exc:
        raise JobError(422, str(exc)) from None
    presets = preset_names()
    if body.preset not in presets:
        raise JobError(422, f"unknown preset {body.preset!r}; known: {', '.join(presets)}")
    if body.seconds is not None and body.seconds > settings.max_seconds_per_run:
        raise JobError(422, f"seconds must be at most {settings.max_seconds_per_run:g}")
    areas = []
    for name in body.areas:
        try:
            areas.append(ensure_area(session, name))
        except CatalogError as exc:
            raise JobError(422, str(exc)) from None
    _refuse_retired(session, areas)
    n_runs = body.runs * len(areas)
    if n_runs > settings.max_runs_per_job:
        raise JobError(422, f"a job may have at most {settings.max_runs_per_job} runs "
                            f"(areas x runs), this one has {n_runs}")
    check_quotas(session, settings, user, n_runs)
    job = Job(user_id=user.id, planner_id=planner.id, preset=body.preset, seconds=body.seconds,
              runs_per_area=body.runs, idempotency_key=idempotency_key, request_hash=digest,
              rerun_of_id=rerun_of, group_id=group_id)
    session.add(job)
    session.flush()
    now = utcnow()
    runs = [
        Run(job_id=job.id, area_id=area.id, seed=seed, preset=body.preset,
            seconds=float(body.seconds if body.seconds is not None else area.plateau_s),
            status=RunState.QUEUED.value, enqueued_at=now)
        for area in areas for seed in range(body.runs)
    ]
    session.add_all(runs)
    session.flush()
    return Created(job, [(r.id, r.seconds) for r in runs], replayed=False)


def _refuse_retired(session: Session, areas: list[AreaRow]) -> None:
    """409 for a held-out area of a generation rotated away: its results stay, but no new run
    joins them."""
    heldout = [a for a in areas if a.split == HELDOUT_SPLIT]
    if not heldout:
        return
    current = current_generation(session)
    for area in heldout:
        if area.heldout_generation != current:
            raise JobError(409, f"area {area.name!r} belongs to held-out generation "
                                f"{area.heldout_generation}, which was rotated away (the current "
                                f"one is {current})")


def check_quotas(session: Session, settings: Settings, user: User, new_runs: int) -> None:
    """429 when the user is over a quota. Admins have none. Jobs whose every run failed for a
    platform reason do not count."""
    if user.is_admin:
        return
    # One check at a time per user, whichever API process serves it: two concurrent requests
    # must not both fit under a quota they exceed together. (SQLite's writers are serialized
    # already; PostgreSQL holds the user's row until the job is committed.)
    session.execute(select(User.id).where(User.id == user.id).with_for_update())
    if settings.quota_jobs_per_day:
        platform_only = ~exists().where(
            and_(Run.job_id == Job.id,
                 ~and_(Run.status == RunState.FAILED.value,
                       Run.failure_kind == FailureKind.PLATFORM.value)))
        recent = session.scalar(
            select(func.count(Job.id)).where(
                Job.user_id == user.id, Job.created_at >= utcnow() - timedelta(days=1),
                ~platform_only)
        ) or 0
        if recent >= settings.quota_jobs_per_day:
            raise JobError(429, f"quota reached: at most {settings.quota_jobs_per_day} jobs per "
                                "day; try again later")
    if settings.quota_concurrent_runs:
        active = session.scalar(
            select(func.count(Run.id)).join(Job).where(Job.user_id == user.id,
                                                       Run.status.in_(ACTIVE_STATES))
        ) or 0
        if active + new_runs > settings.quota_concurrent_runs:
            raise JobError(429, f"quota reached: at most {settings.quota_concurrent_runs} queued "
                                f"or running runs at once; {active} are active and this job "
                                f"adds {new_runs}")


def may_manage(user: User, job: Job) -> bool:
    return user.is_admin or job.user_id == user.id


def cancel_job(session: Session, job: Job) -> None:
    """Queued runs end as cancelled now; running ones are asked to stop (within seconds)."""
    now = utcnow()
    for run in job.runs:
        if run.status == RunState.QUEUED.value:
            run.status = RunState.CANCELLED.value
            run.finished_at = now
            run.error = "cancelled before it started"
        elif run.status == RunState.RUNNING.value:
            run.cancel_requested = True
    session.flush()


def rerun_job(session: Session, settings: Settings, user: User, job: Job) -> Created:
    """A new job with `job`'s request, in `job`'s group if it has one (where it stands in for
    `job`: see `server.groups.current_jobs`)."""
    body = JobCreate(planner=job.planner.key, areas=_job_areas(job), runs=job.runs_per_area,
                     seconds=job.seconds, preset=job.preset)
    return create_job(session, settings, user, body, rerun_of=job.id, group_id=job.group_id)


def _job_areas(job: Job) -> list[str]:
    names: list[str] = []
    for run in job.runs:
        if run.area.name not in names:
            names.append(run.area.name)
    return names


def job_status(job: Job) -> tuple[str, float]:
    """The job's state and progress (0-1), derived from its runs."""
    return status_of([(r.status, r.progress) for r in job.runs])


def status_of(runs: Sequence[tuple[str, float]]) -> tuple[str, float]:
    """A job's state and progress (0-1) from its runs' (status, progress), in run order."""
    states = [s for s, _ in runs]
    if not states:
        return RunState.SUCCEEDED.value, 1.0
    finals = [RunState(s).final for s in states]
    progress = sum(1.0 if f else p for f, (_, p) in zip(finals, runs, strict=True))
    progress /= len(states)
    if all(finals):
        if RunState.FAILED.value in states:
            return RunState.FAILED.value, 1.0
        if RunState.CANCELLED.value in states:
            return RunState.CANCELLED.value, 1.0
        return RunState.SUCCEEDED.value, 1.0
    if all(s == RunState.QUEUED.value for s in states):
        return RunState.QUEUED.value, progress
    return RunState.RUNNING.value, progress


def job_out(job: Job) -> JobOut:
    status, progress = job_status(job)
    return JobOut(
        id=job.id, status=status, progress=round(progress, 4), planner=job.planner.key,
        preset=job.preset, seconds=job.seconds, runs_per_area=job.runs_per_area,
        areas=_job_areas(job), owner=job.user.name, created_at=job.created_at,
        rerun_of=job.rerun_of_id, group_id=job.group_id, reference=job.reference,
        runs=[RunBrief(id=r.id, area=r.area.name, seed=r.seed, status=r.status,
                       progress=round(1.0 if RunState(r.status).final else r.progress, 4))
              for r in job.runs],
    )


_JOBS, _RUNS = Job.__table__, Run.__table__
_PLANNERS, _USERS, _AREAS = PlannerRow.__table__, User.__table__, AreaRow.__table__
# One round trip for the job and its runs (a job without runs gives one row of NULL run
# columns), as plain rows: polling reads this every few seconds per client, and loading the
# ORM objects behind `job_out` cost ~10 ms per answer.
_READ_JOB = (
    select(_JOBS.c.id, _JOBS.c.preset, _JOBS.c.seconds, _JOBS.c.runs_per_area,
           _JOBS.c.created_at, _JOBS.c.rerun_of_id, _JOBS.c.group_id,
           _JOBS.c.reference,
           _PLANNERS.c.name.label("planner_name"), _PLANNERS.c.version.label("planner_version"),
           _USERS.c.name.label("owner"), _RUNS.c.id.label("run_id"),
           _AREAS.c.name.label("area"), _RUNS.c.seed, _RUNS.c.status, _RUNS.c.progress)
    .select_from(
        _JOBS.join(_PLANNERS, _PLANNERS.c.id == _JOBS.c.planner_id)
        .join(_USERS, _USERS.c.id == _JOBS.c.user_id)
        .outerjoin(_RUNS, _RUNS.c.job_id == _JOBS.c.id)
        .outerjoin(_AREAS, _AREAS.c.id == _RUNS.c.area_id))
    .where(_JOBS.c.id == bindparam("job_id"))
    .order_by(_RUNS.c.id)
)


def read_job(conn: Connection, job_id: int) -> JobOut | None:
    """What `job_out` answers for the job, read with one Core query; None if there is none."""
    rows = conn.execute(_READ_JOB, {"job_id": job_id}).all()
    if not rows:
        return None
    job = rows[0]
    runs = [r for r in rows if r.run_id is not None]
    status, progress = status_of([(r.status, r.progress) for r in runs])
    areas: list[str] = []
    for r in runs:
        if r.area not in areas:
            areas.append(r.area)
    return JobOut(
        id=job.id, status=status, progress=round(progress, 4),
        planner=f"{job.planner_name}-v{job.planner_version}", preset=job.preset,
        seconds=job.seconds, runs_per_area=job.runs_per_area, areas=areas, owner=job.owner,
        created_at=job.created_at, rerun_of=job.rerun_of_id, group_id=job.group_id,
        reference=bool(job.reference),
        runs=[RunBrief(id=r.run_id, area=r.area, seed=r.seed, status=r.status,
                       progress=round(1.0 if RunState(r.status).final else r.progress, 4))
              for r in runs],
    )
