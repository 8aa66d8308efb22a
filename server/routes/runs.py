"""Runs: details, metric curves, artifacts and the log."""

from __future__ import annotations

import contextlib
from typing import Annotated, Any

import numpy as np
from fastapi import APIRouter, HTTPException, Query
from fastapi.responses import FileResponse, PlainTextResponse
from sqlalchemy import select
from sqlalchemy.orm import Session, selectinload

from server.deps import IdPath, OptionalUserDep, SessionDep, SettingsDep, UserDep
from server.jobs import may_manage
from server.models import Artifact, Job, MetricSeries, Run, RunState, User
from server.schemas import ArtifactOut, ErrorBody, ResultOut, RunOut, SeriesOut
from server.split_access import refuse_hidden, scene_hidden
from server.storage import ArtifactStoreError, settings_store

router = APIRouter(prefix="/runs", tags=["runs"])

_ERRORS: dict[int | str, dict[str, Any]] = {404: {"model": ErrorBody}}
ARTIFACT_FILES = {
    # kind: (download name, content type); nothing here is rendered by a browser as a page.
    "recording": ("recording.npz", "application/octet-stream"),
    "mesh": ("mesh.ply", "application/octet-stream"),
    "log": ("run.log", "text/plain; charset=utf-8"),
    "result": ("result.json", "application/json"),
}
PRIVATE_KINDS = {"log"}


def _load(session: Session, run_id: int) -> Run:
    run = session.scalar(select(Run).where(Run.id == run_id).options(
        selectinload(Run.job).selectinload(Job.planner), selectinload(Run.area),
        selectinload(Run.result), selectinload(Run.artifacts)))
    if run is None:
        raise HTTPException(404, f"no run with id {run_id}")
    return run


def _series(blob: bytes) -> list[float]:
    return [float(x) for x in np.frombuffer(blob, dtype="<f4")]


HIDDEN_ERROR = "the run failed; the details of a held-out run are shown to admins only"


def _result_out(run: Run, hidden: bool) -> ResultOut | None:
    if run.result is None:
        return None
    out = ResultOut.model_validate(run.result, from_attributes=True)
    if hidden:  # the record names the area's content hash and the flown scene's files
        out.record = None
    return out


@router.get("/{run_id}", response_model=RunOut, responses=_ERRORS)
def get_run(run_id: IdPath, session: SessionDep, user: OptionalUserDep) -> RunOut:
    """The run; on a held-out area, without its files, record and error details unless the
    caller is an admin (`server.split_access`)."""
    return read_run(session, run_id, user)


def read_run(session: Session, run_id: int, user: User | None) -> RunOut:
    """What `GET /runs/{id}` answers `user` (None: an anonymous visitor)."""
    run = _load(session, run_id)
    hidden = scene_hidden(run.area, user)
    error = HIDDEN_ERROR if hidden and run.error else run.error
    return RunOut(
        id=run.id, job_id=run.job_id, planner=run.job.planner.key, area=run.area.name,
        seed=run.seed, preset=run.preset, seconds=run.seconds, status=run.status,
        progress=1.0 if RunState(run.status).final else run.progress, sim_time_s=run.sim_time_s,
        attempts=run.attempts, worker=run.worker, started_at=run.started_at,
        finished_at=run.finished_at, wall_time_s=run.wall_time_s, error=error,
        failure_kind=run.failure_kind, result=_result_out(run, hidden),
        artifacts=[] if hidden else [
            ArtifactOut(kind=a.kind, size_bytes=a.size_bytes, sha256=a.sha256,
                        content_type=a.content_type,
                        url=f"/api/v1/runs/{run.id}/artifacts/{a.kind}")
            for a in run.artifacts if a.kind not in PRIVATE_KINDS],
        split=run.area.split, heldout_generation=run.area.heldout_generation,
    )


@router.get("/{run_id}/series", response_model=SeriesOut, responses=_ERRORS)
def get_series(run_id: IdPath, session: SessionDep) -> SeriesOut:
    if session.get(Run, run_id) is None:
        raise HTTPException(404, f"no run with id {run_id}")
    series = session.get(MetricSeries, run_id)
    if series is None:
        raise HTTPException(404, f"run {run_id} has no metric series yet: it has not finished")
    return SeriesOut(run_id=run_id, time_s=_series(series.time_s),
                     explored_volume_m3=_series(series.explored_volume_m3),
                     recall_time_s=_series(series.recall_time_s),
                     surface_recall=_series(series.surface_recall))


@router.get("/{run_id}/artifacts/{kind}", response_class=FileResponse,
            responses={**_ERRORS, 200: {"content": {"application/octet-stream": {}}}})
def get_artifact(run_id: IdPath, kind: str, session: SessionDep, settings: SettingsDep,
                 user: OptionalUserDep) -> FileResponse:
    if kind not in ARTIFACT_FILES or kind in PRIVATE_KINDS:
        raise HTTPException(404, f"unknown artifact kind {kind!r}; known: "
                                 f"{', '.join(sorted(set(ARTIFACT_FILES) - PRIVATE_KINDS))}")
    run = session.get(Run, run_id)
    if run is not None:
        refuse_hidden(run.area, user)
    artifact = session.scalar(select(Artifact).where(Artifact.run_id == run_id,
                                                     Artifact.kind == kind))
    if artifact is None:
        raise HTTPException(404, f"run {run_id} has no {kind} artifact")
    try:
        path = settings_store(settings).open_path(artifact.location)
    except ArtifactStoreError as exc:
        raise HTTPException(404, str(exc)) from None
    filename, content_type = ARTIFACT_FILES[kind]
    return FileResponse(path, media_type=content_type,
                        filename=f"run-{run_id}-{filename}",
                        headers={"X-Content-Type-Options": "nosniff"})


@router.get("/{run_id}/log", response_class=PlainTextResponse,
            responses={**_ERRORS, 403: {"model": ErrorBody}})
def get_log(run_id: IdPath, session: SessionDep, settings: SettingsDep, user: UserDep,
            tail: Annotated[int, Query(ge=1, le=100_000)] = 200) -> PlainTextResponse:
    run = _load(session, run_id)
    if not may_manage(user, run.job):
        raise HTTPException(403, "only the run's owner or an admin may read its log")
    refuse_hidden(run.area, user, status=403)  # a planner's log may describe its scene
    text = run.log_tail
    artifact = next((a for a in run.artifacts if a.kind == "log"), None)
    if artifact is not None:
        with contextlib.suppress(ArtifactStoreError):  # else the live tail is still there
            text = settings_store(settings).open_path(artifact.location).read_text(
                errors="replace")
    lines = text.splitlines()[-tail:]
    return PlainTextResponse("\n".join(lines) + ("\n" if lines else ""),
                             headers={"X-Content-Type-Options": "nosniff"})
