"""Job groups: a whole suite (planners x areas x runs) submitted at once (`flybo benchmark`).

A group holds one job per planner, made by `server.jobs.create_job` in the caller's
transaction, so a group is stored whole or not at all and its runs are enqueued only after the
commit, as a job's are. With `time_scale` each area runs for a fraction of its own plateau
time; a job has one duration, so such a group holds one job per planner and area.
"""

from __future__ import annotations

import hashlib
import json
from collections import Counter
from dataclasses import dataclass, field
from datetime import datetime

from pydantic import BaseModel, ConfigDict, Field, field_validator
from sqlalchemy import select
from sqlalchemy.orm import Session

from server.catalog import CatalogError, ensure_area, find_planner
from server.heldout import ensure_heldout_areas
from server.jobs import JobError, cancel_job, check_quotas, create_job, job_status
from server.models import LEGACY_VERSION, AreaRow, Job, JobGroup, PlannerRow, RunState, User
from server.schemas import JobCreate
from server.settings import Settings

ALL = "all"
STATES = tuple(s.value for s in RunState)


class GroupCreate(BaseModel):
    model_config = ConfigDict(extra="forbid")

    planners: list[str] = Field(min_length=1, max_length=32,
                                description="planner names (name or name-vN), or ['all'] for "
                                            "every built-in planner")
    areas: list[str] = Field(min_length=1, max_length=64,
                             description="area names, or ['all'] for every built-in area")
    runs: int = Field(default=5, ge=1, le=100, description="runs (seeds 0..runs-1) per area")
    preset: str = Field(default="default", min_length=1, max_length=32)
    name: str | None = Field(default=None, min_length=1, max_length=128)
    seconds: float | None = Field(default=None, gt=0, allow_inf_nan=False,
                                  description="simulated seconds of every run; default: each "
                                              "area's plateau time")
    time_scale: float | None = Field(default=None, gt=0, le=1, allow_inf_nan=False,
                                     description="run each area for this fraction of its "
                                                 "plateau time (not with `seconds`)")
    heldout: bool = Field(default=False, description="also run the held-out counterparts of "
                          "the areas (the current generation's), which rank on the held-out "
                          "board")

    @field_validator("planners", "areas")
    @classmethod
    def _unique_names(cls, value: list[str]) -> list[str]:
        if len(set(value)) != len(value):
            raise ValueError("names must not repeat")
        if ALL in value and len(value) > 1:
            raise ValueError(f"'{ALL}' stands alone")
        return value


class StatusCounts(BaseModel):
    queued: int = 0
    running: int = 0
    succeeded: int = 0
    failed: int = 0
    cancelled: int = 0


class PlannerProgress(BaseModel):
    planner: str
    jobs: list[int] = Field(description="the jobs counted: a re-run stands in for the job it "
                                        "re-runs")
    runs: int
    done: int = Field(description="runs in a final state")
    progress: float = Field(description="0-1, counting running runs by their progress")
    by_status: StatusCounts
    simulated_s: float = Field(description="simulated seconds the runs were asked for")


class GroupOut(BaseModel):
    id: int
    name: str
    owner: str
    preset: str
    runs_per_area: int
    seconds: float | None
    time_scale: float | None
    areas: list[str]
    created_at: datetime
    status: str
    progress: float
    runs: int
    done: int
    by_status: StatusCounts
    planners: list[PlannerProgress]


@dataclass
class GroupCreated:
    group: JobGroup
    runs: list[tuple[int, float]] = field(default_factory=list)  # (run id, seconds) to enqueue
    replayed: bool = False


def request_hash(body: GroupCreate) -> str:
    fields = body.model_dump(mode="json")
    if not fields["heldout"]:  # as before the option existed: stored keys keep their hashes
        del fields["heldout"]
    canonical = json.dumps(fields, sort_keys=True)
    return hashlib.sha256(canonical.encode()).hexdigest()


def _planner_names(session: Session, names: list[str]) -> list[str]:
    """`names` checked against the catalog (422 listing the known ones), or every built-in
    planner's default (newest original) version for ['all']."""
    if names == [ALL]:
        names = sorted(set(session.scalars(select(PlannerRow.name)
                                           .where(PlannerRow.builtin.is_(True)))))
        if not names:
            raise JobError(422, "no built-in planner is registered")
        # Each name as a job names it: the registry's default version.
        return [find_planner(session, name).key for name in names]
    keys = []
    for name in names:
        try:
            keys.append(find_planner(session, name).key)
        except CatalogError as exc:
            raise JobError(422, str(exc)) from None
    if len(set(keys)) != len(keys):
        raise JobError(422, "planners must not repeat (a name and its version count as one)")
    return keys


def _areas(session: Session, names: list[str]) -> list[AreaRow]:
    if names == [ALL]:
        from areas.registry import area_names  # the simulation stack, on use

        names = area_names()
    rows = []
    for name in names:
        try:
            rows.append(ensure_area(session, name))
        except CatalogError as exc:
            raise JobError(422, str(exc)) from None
    return rows


def _heldout_areas(session: Session, settings: Settings, names: list[str],
                   benchmark_version: str) -> list[AreaRow]:
    """The current generation's held-out areas of the built-in areas `names` (['all']: of
    every one the service holds out)."""
    wanted = set(settings.heldout_areas) if names == [ALL] else set(names)
    families = [name for name in settings.heldout_areas if name in wanted]
    if not families:
        raise JobError(422, "none of these areas has a held-out counterpart; held out: "
                            f"{', '.join(settings.heldout_areas) or 'none'}")
    return ensure_heldout_areas(session, settings.heldout_key, benchmark_version, families)


def create_group(session: Session, settings: Settings, user: User, body: GroupCreate, *,
                 idempotency_key: str | None = None,
                 benchmark_version: str = LEGACY_VERSION) -> GroupCreated:
    """The group and its jobs, flushed in the caller's transaction; the caller commits, then
    enqueues `runs`. Any refusal raises `JobError` before anything is committed."""
    digest = request_hash(body)
    if idempotency_key is not None:
        previous = session.scalar(select(JobGroup).where(
            JobGroup.user_id == user.id, JobGroup.idempotency_key == idempotency_key))
        if previous is not None:
            if previous.request_hash != digest:
                raise JobError(409, "this Idempotency-Key was used for a different request")
            return GroupCreated(previous, replayed=True)
    if body.seconds is not None and body.time_scale is not None:
        raise JobError(422, "give either seconds or time_scale, not both")
    planners = _planner_names(session, body.planners)
    areas = _areas(session, body.areas)
    if body.heldout:
        areas += _heldout_areas(session, settings, body.areas, benchmark_version)
    # The whole group against the concurrent-runs quota first, so that a group is refused
    # whole rather than after some of its jobs; create_job checks each job again.
    check_quotas(session, settings, user, len(planners) * len(areas) * body.runs)
    group = JobGroup(user_id=user.id, name=body.name or f"{len(planners)} planner(s) x "
                     f"{len(areas)} area(s) x {body.runs} run(s)", preset=body.preset,
                     runs_per_area=body.runs, seconds=body.seconds, time_scale=body.time_scale,
                     idempotency_key=idempotency_key, request_hash=digest)
    session.add(group)
    session.flush()
    created = GroupCreated(group)
    for planner in planners:
        if body.time_scale is None:
            batches = [([a.name for a in areas], body.seconds)]
        else:
            batches = [([a.name], round(a.plateau_s * body.time_scale, 3)) for a in areas]
        for names, seconds in batches:
            made = create_job(session, settings, user, JobCreate(
                planner=planner, areas=names, runs=body.runs, seconds=seconds,
                preset=body.preset), group_id=group.id)
            created.runs.extend(made.runs)
    session.flush()
    return created


def cancel_group(session: Session, group: JobGroup) -> None:
    for job in group.jobs:
        cancel_job(session, job)


def _counts(states: list[str]) -> StatusCounts:
    counted = Counter(states)
    return StatusCounts(**{s: counted.get(s, 0) for s in STATES})


def current_jobs(group: JobGroup) -> list[Job]:
    """The group's jobs that no re-run in the group replaces: of a job and its re-runs (and
    theirs), only the newest, in the place of the first. A re-run asks again for the same
    planner, areas and seeds, so counting both would count those runs twice and keep an
    earlier failure in the group's state after the re-run succeeded."""
    by_id = {job.id: job for job in group.jobs}
    newest: dict[int, Job] = {}  # first job's id -> its newest re-run (or itself)
    for job in sorted(group.jobs, key=lambda j: j.id):
        first = job
        while first.rerun_of_id is not None and first.rerun_of_id in by_id:
            first = by_id[first.rerun_of_id]
        newest[first.id] = job  # ids grow: a later job of the line is a later re-run
    return list(newest.values())


def group_out(group: JobGroup) -> GroupOut:
    current = current_jobs(group)
    by_planner: dict[str, list[Job]] = {}
    for job in current:
        by_planner.setdefault(job.planner.key, []).append(job)
    planners = []
    for planner, jobs in by_planner.items():
        runs = [r for j in jobs for r in j.runs]
        finals = [RunState(r.status).final for r in runs]
        progress = sum(1.0 if f else r.progress for f, r in zip(finals, runs, strict=True))
        planners.append(PlannerProgress(
            planner=planner, jobs=[j.id for j in jobs], runs=len(runs), done=sum(finals),
            progress=round(progress / len(runs), 4) if runs else 1.0,
            by_status=_counts([r.status for r in runs]),
            simulated_s=sum(r.seconds for r in runs)))
    runs = [r for j in current for r in j.runs]
    areas: list[str] = []
    for run in runs:
        if run.area.name not in areas:
            areas.append(run.area.name)
    total = len(runs)
    done = sum(p.done for p in planners)
    progress = sum(p.progress * p.runs for p in planners) / total if total else 1.0
    return GroupOut(
        id=group.id, name=group.name, owner=group.user.name, preset=group.preset,
        runs_per_area=group.runs_per_area, seconds=group.seconds, time_scale=group.time_scale,
        areas=areas, created_at=group.created_at, status=_status(current),
        progress=round(progress, 4), runs=total, done=done,
        by_status=_counts([r.status for r in runs]), planners=planners)


def _status(jobs: list[Job]) -> str:
    """As a job's (`server.jobs.job_status`), over the group's current jobs."""
    states = [job_status(j)[0] for j in jobs]
    if not states:
        return RunState.SUCCEEDED.value
    if all(RunState(s).final for s in states):
        for worst in (RunState.FAILED.value, RunState.CANCELLED.value):
            if worst in states:
                return worst
        return RunState.SUCCEEDED.value
    if all(s == RunState.QUEUED.value for s in states):
        return RunState.QUEUED.value
    return RunState.RUNNING.value
