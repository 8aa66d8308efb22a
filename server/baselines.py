"""Baseline datasets in and out of a service's database (`docs/baselines.md`).

`export_dataset` gathers the succeeded runs of built-in planners of one benchmark version (their
results, series and reproducibility records; never meshes or recordings) into a `Dataset`.
`import_dataset` stores a dataset's runs as reference results: jobs marked `reference`, owned by
the user `REFERENCE_USER`, their runs succeeded with the dataset's results and series. It writes
in the caller's session and raises before anything is committed on any conflict, so the
caller's one transaction stores all of it or nothing. Runs already stored as reference results
(same planner, area, preset, seed and benchmark version) are skipped: importing twice adds
nothing.
"""

from __future__ import annotations

import base64
import hashlib
from collections import defaultdict
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from server.baseline_format import (
    FORMAT,
    FORMAT_VERSION,
    AreaEntry,
    Dataset,
    DatasetError,
    PlannerEntry,
    ResultEntry,
    RunEntry,
    SeriesEntry,
    SuiteEntry,
)
from server.models import (
    PUBLIC_SPLIT,
    AreaRow,
    Job,
    MetricSeries,
    PlannerRow,
    Run,
    RunResult,
    RunState,
    User,
)
from server.security import REFERENCE_USER

_RESULT_FIELDS = tuple(ResultEntry.model_fields)
_SERIES_FIELDS = tuple(SeriesEntry.model_fields)


def export_dataset(session: Session, benchmark_version: str,
                   presets: Sequence[str] | None = None) -> Dataset:
    """The succeeded runs of built-in planners on public areas made by `benchmark_version` (in
    `presets` only, when given), ordered by preset, planner, area and seed."""
    query = (select(Run, RunResult, MetricSeries, PlannerRow, AreaRow)
             .join(RunResult, RunResult.run_id == Run.id)
             .outerjoin(MetricSeries, MetricSeries.run_id == Run.id)
             .join(Job, Run.job_id == Job.id)
             .join(PlannerRow, Job.planner_id == PlannerRow.id)
             .join(AreaRow, Run.area_id == AreaRow.id)
             .where(Run.status == RunState.SUCCEEDED.value, PlannerRow.builtin.is_(True),
                    RunResult.benchmark_version == benchmark_version,
                    # A dataset is published: held-out areas' rows hold their secret seeds.
                    AreaRow.split == PUBLIC_SPLIT))
    if presets:
        query = query.where(Run.preset.in_(list(presets)))
    planners: dict[str, PlannerEntry] = {}
    areas: dict[str, AreaEntry] = {}
    runs: list[RunEntry] = []
    for run, result, series, planner, area in session.execute(query):
        planners[planner.key] = PlannerEntry(
            name=planner.name, version=planner.version, builtin=planner.builtin,
            description=planner.description, reference=planner.reference,
            method=planner.method, code_hash=planner.code_hash, config=planner.config)
        areas[area.name] = AreaEntry(name=area.name, builtin=area.builtin,
                                     content_hash=area.content_hash, plateau_s=area.plateau_s,
                                     voxel_size=area.voxel_size, stats=area.stats)
        runs.append(_run_entry(run, result, series, planner.key, area.name))
    runs.sort(key=lambda r: (r.preset, r.planner, r.area, r.seed))
    return Dataset(format=FORMAT, format_version=FORMAT_VERSION,
                   benchmark_version=benchmark_version, exported_at=datetime.now(UTC),
                   suite=suite_of(runs), planners=sorted(planners.values(), key=lambda p: p.key),
                   areas=sorted(areas.values(), key=lambda a: a.name), runs=runs)


def _run_entry(run: Run, result: RunResult, series: MetricSeries | None, planner: str,
               area: str) -> RunEntry:
    return RunEntry(
        planner=planner, area=area, seed=run.seed, preset=run.preset, seconds=run.seconds,
        attempts=run.attempts, worker=run.worker, sim_time_s=run.sim_time_s,
        enqueued_at=run.enqueued_at, started_at=run.started_at, finished_at=run.finished_at,
        wall_time_s=run.wall_time_s,
        result=ResultEntry(**{k: getattr(result, k) for k in _RESULT_FIELDS}),
        series=None if series is None else SeriesEntry(**{
            k: base64.b64encode(getattr(series, k)).decode("ascii") for k in _SERIES_FIELDS}))


def suite_of(runs: Iterable[RunEntry]) -> SuiteEntry:
    runs = list(runs)
    starts = [r.started_at for r in runs if r.started_at is not None]
    ends = [r.finished_at for r in runs if r.finished_at is not None]
    first, last = (min(starts) if starts else None), (max(ends) if ends else None)
    return SuiteEntry(
        runs=len(runs), simulated_s=sum(r.result.simulated_until_s for r in runs),
        wall_time_s=(last - first).total_seconds() if first and last else None,
        run_wall_time_s=sum(r.wall_time_s or 0.0 for r in runs),
        first_started_at=first, last_finished_at=last)


@dataclass(frozen=True)
class Imported:
    benchmark_version: str
    imported: int
    skipped: int
    jobs: list[int]


def import_dataset(session: Session, dataset: Dataset, fingerprint: str) -> Imported:
    """Store `dataset`'s runs as reference results in `session` (flushed, not committed).

    `fingerprint` (the file's hash) becomes the jobs' request hash. Raises `DatasetError` when
    a planner or area of the dataset is stored here with other content; the caller rolls back.
    """
    planners = {p.key: _planner_row(session, p) for p in dataset.planners}
    areas = {a.name: _area_row(session, a) for a in dataset.areas}
    have = _stored_reference_runs(session, dataset.benchmark_version)
    fresh = [r for r in dataset.runs if (*r.cell, r.seed) not in have]
    owner = _reference_user(session)
    by_job: dict[tuple[str, str], list[RunEntry]] = defaultdict(list)
    for run in fresh:
        by_job[(run.planner, run.preset)].append(run)
    jobs = []
    for (planner, preset), runs in sorted(by_job.items()):
        per_area: dict[str, int] = defaultdict(int)
        for run in runs:
            per_area[run.area] += 1
        seconds = {r.seconds for r in runs}
        job = Job(user_id=owner.id, planner_id=planners[planner].id, preset=preset,
                  seconds=seconds.pop() if len(seconds) == 1 else None,
                  runs_per_area=max(per_area.values()), request_hash=fingerprint[:64],
                  reference=True, created_at=dataset.exported_at)
        session.add(job)
        session.flush()
        jobs.append(job.id)
        for run in runs:
            _add_run(session, job, areas[run.area], run)
    session.flush()
    return Imported(dataset.benchmark_version, len(fresh), len(dataset.runs) - len(fresh), jobs)


def _add_run(session: Session, job: Job, area: AreaRow, entry: RunEntry) -> None:
    run = Run(job_id=job.id, area_id=area.id, seed=entry.seed, preset=entry.preset,
              seconds=entry.seconds, status=RunState.SUCCEEDED.value, attempts=entry.attempts,
              worker=entry.worker, progress=1.0, sim_time_s=entry.sim_time_s,
              enqueued_at=entry.enqueued_at, started_at=entry.started_at,
              heartbeat_at=entry.finished_at, finished_at=entry.finished_at,
              wall_time_s=entry.wall_time_s)
    session.add(run)
    session.flush()
    session.add(RunResult(run_id=run.id, **entry.result.model_dump()))
    if entry.series is not None:
        session.add(MetricSeries(run_id=run.id, **entry.series.blobs()))


def _planner_row(session: Session, entry: PlannerEntry) -> PlannerRow:
    row = session.scalar(select(PlannerRow).where(PlannerRow.name == entry.name,
                                                  PlannerRow.version == entry.version))
    if row is None:
        row = PlannerRow(name=entry.name, version=entry.version, builtin=entry.builtin,
                         description=entry.description, reference=entry.reference,
                         method=entry.method, code_hash=entry.code_hash, config=entry.config)
        session.add(row)
        session.flush()
    elif row.builtin != entry.builtin or (row.code_hash or "") != entry.code_hash:
        raise DatasetError(f"planner {entry.key} is stored here with other code; the "
                           "dataset's results are not of this planner")
    return row


def _area_row(session: Session, entry: AreaEntry) -> AreaRow:
    row = session.scalar(select(AreaRow).where(AreaRow.name == entry.name))
    if row is None:
        row = AreaRow(name=entry.name, builtin=entry.builtin, content_hash=entry.content_hash,
                      plateau_s=entry.plateau_s, voxel_size=entry.voxel_size, stats=entry.stats)
        session.add(row)
        session.flush()
    elif row.content_hash != entry.content_hash:
        raise DatasetError(f"area {entry.name} is stored here with other content (hash "
                           f"{row.content_hash[:12]}, the dataset's {entry.content_hash[:12]})")
    return row


def _stored_reference_runs(session: Session,
                           benchmark_version: str) -> set[tuple[str, str, str, int]]:
    rows = session.execute(
        select(PlannerRow.name, PlannerRow.version, AreaRow.name, Run.preset, Run.seed)
        .join(Job, Run.job_id == Job.id).join(PlannerRow, Job.planner_id == PlannerRow.id)
        .join(AreaRow, Run.area_id == AreaRow.id).join(RunResult, RunResult.run_id == Run.id)
        .where(Job.reference.is_(True), RunResult.benchmark_version == benchmark_version))
    return {(f"{name}-v{version}", area, preset, seed)
            for name, version, area, preset, seed in rows}


def _reference_user(session: Session) -> User:
    user = session.scalar(select(User).where(User.name == REFERENCE_USER))
    if user is None:
        user = User(name=REFERENCE_USER, is_admin=False)
        session.add(user)
        session.flush()
    return user


def database_is_empty(session: Session) -> bool:
    """No job was ever stored: a service's first start."""
    return not session.scalar(select(func.count(Job.id)))


def fingerprint(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()
