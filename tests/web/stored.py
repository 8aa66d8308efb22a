"""Hand-made stored results for the page tests: rows written through the ORM models, with
numbers chosen so that the expected tables, ranks and curves can be worked out by hand."""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import Any

import numpy as np
from sqlalchemy.orm import Session

from server.models import (
    AreaRow,
    Artifact,
    Job,
    MetricSeries,
    PlannerRow,
    Run,
    RunResult,
    RunState,
    User,
)

HOSTILE = "<script>alert('x')</script>"


@functools.cache
def current_version() -> str:
    """The benchmark version of this tree as this process's reproducibility records name it
    (read once per process, as a worker reads it): the hand-made rows, the runs flown in the
    tests' process and the apps the tests make all agree on it, even if the tree changes
    meanwhile."""
    from flybo.record import _process_code

    version = _process_code()[1]["benchmark_version"]
    assert isinstance(version, str), "this tree's benchmark version could not be read"
    return version


def f32(values: Sequence[float]) -> bytes:
    return np.asarray(values, dtype="<f4").tobytes()


def add_area(session: Session, name: str, title: str | None = None) -> AreaRow:
    row = AreaRow(name=name, builtin=True, content_hash="0" * 64, plateau_s=700.0,
                  voxel_size=0.1, stats={"title": title or name.upper(), "rooms": 3,
                                         "levels": 1, "indoor": True, "faces": 100,
                                         "bounding_volume_m": [20.0, 20.0, 2.5]})
    session.add(row)
    session.flush()
    return row


def add_planner(session: Session, name: str, *, builtin: bool = True,
                description: str = "a test planner", owner: User | None = None,
                method: str = "") -> PlannerRow:
    row = PlannerRow(name=name, version=1, builtin=builtin, description=description,
                     reference="a reference", method=method,
                     config={"defaults": {"step_m": 1.0}}, owner_id=owner.id if owner else None)
    session.add(row)
    session.flush()
    return row


def add_job(session: Session, user: User, planner: PlannerRow, preset: str = "default") -> Job:
    job = Job(user_id=user.id, planner_id=planner.id, preset=preset, seconds=None,
              runs_per_area=1, request_hash="0" * 64)
    session.add(job)
    session.flush()
    return job


def add_run(session: Session, job: Job, area: AreaRow, seed: int, *, coverage: float,
            fscore: float | None, volume: Sequence[float], recall: Sequence[float],
            status: str = RunState.SUCCEEDED.value, log: str = "",
            benchmark_version: str | None = None, metrics: dict[str, Any] | None = None,
            time_to_90: float | None = None) -> Run:
    """A finished run with its result, its series (one volume sample per second, one recall
    sample per 20 s) and a mesh artifact row, made by `benchmark_version` (this tree's by
    default). Its metrics block: `metrics`, else the row's numbers with the explored
    observable volume equal to the last volume sample and `time_to_90` ('legacy' rows have
    none)."""
    version = benchmark_version or current_version()
    if metrics is None and version != "legacy":
        metrics = {"coverage": coverage, "explored_observable_m3": float(volume[-1]),
                   "fscore": fscore, "precision": fscore, "recall": fscore, "rmse_m": 0.02,
                   "path_length_m": 10.0 + seed, "collisions": 0, "safety_stops": 0,
                   "iterations": 5 + seed, "time_to_90_coverage_s": time_to_90}
    run = Run(job_id=job.id, area_id=area.id, seed=seed, preset=job.preset,
              seconds=float(len(volume) - 1), status=status, progress=1.0,
              sim_time_s=float(len(volume) - 1), attempts=1, log_tail=log)
    session.add(run)
    session.flush()
    session.add(RunResult(
        run_id=run.id, outcome="succeeded", reason="time limit reached",
        simulated_until_s=run.seconds, explored_volume_m3=volume[-1],
        volume_at_plateau_m3=volume[-1], observable_volume_m3=1000.0, coverage=coverage,
        volumetric_efficiency=volume[-1] / max(run.seconds, 1.0), precision=fscore,
        recall=fscore, fscore=fscore, rmse_m=0.02, collisions=0, path_length_m=10.0 + seed,
        iterations=5 + seed, planning_ms_median=3.0, planning_ms_mean=4.0,
        planning_ms_max=9.0, wall_seconds=1.0, benchmark_version=version, metrics=metrics,
        record=None if version == "legacy" else {"benchmark_version": version, "seed": seed,
                                                 "missing": []}))
    session.add(MetricSeries(
        run_id=run.id, time_s=f32(range(len(volume))), explored_volume_m3=f32(volume),
        recall_time_s=f32([20.0 * (i + 1) for i in range(len(recall))]),
        surface_recall=f32(recall)))
    session.add(Artifact(run_id=run.id, kind="mesh", location=f"runs/{run.id}/mesh.ply",
                         size_bytes=1000, sha256="a" * 64,
                         content_type="application/octet-stream"))
    session.flush()
    return run
