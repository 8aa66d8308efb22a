"""The run task on a real database: exactly-once results, cancellation, lost claims, failures.

The task body (`worker.runner.execute_run`) runs in this process here; the end-to-end tests run
it in real worker processes."""

from __future__ import annotations

import json
import threading
import time
from datetime import timedelta
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from celery.exceptions import SoftTimeLimitExceeded
from sqlalchemy import func, select, update
from sqlalchemy.orm import Session, sessionmaker

from flybo.record import reproducibility_record
from server.db import session_scope
from server.jobs import create_job
from server.models import Artifact, MetricSeries, Run, RunResult, RunState, User, utcnow
from server.schemas import JobCreate
from server.settings import Settings
from server.storage import open_store
from worker.runner import (
    claim,
    execute_run,
    install_record_builder,
    machine_speed_factor,
    measure_speed_in_background,
)


def _job(sessions: sessionmaker[Session], settings: Settings, seconds: float = 8.0,
         runs: int = 1) -> list[int]:
    from server.catalog import sync_builtin_planners

    with session_scope(sessions) as s:
        sync_builtin_planners(s)
        user = s.scalar(select(User).where(User.name == "alice")) or User(name="alice")
        s.add(user)
        s.flush()
        created = create_job(s, settings, user, JobCreate(planner="classic", areas=["maze"],
                                                          runs=runs, seconds=seconds))
    return [run_id for run_id, _ in created.runs]


def _count(sessions: sessionmaker[Session], model: Any, run_id: int) -> int:
    with sessions() as s:
        return s.scalar(select(func.count()).select_from(model).where(model.run_id == run_id)) or 0


def test_a_run_stores_everything_once(sessions: sessionmaker[Session],
                                      settings: Settings) -> None:
    (run_id,) = _job(sessions, settings)
    assert execute_run(run_id, settings) == "succeeded"
    assert execute_run(run_id, settings) == "skipped"  # a duplicate message does nothing
    with sessions() as s:
        run = s.get(Run, run_id)
        assert run is not None and run.status == "succeeded" and run.attempts == 1
        assert run.progress == 1.0 and run.wall_time_s and run.wall_time_s > 0
        assert "succeeded" in run.log_tail
        result = s.get(RunResult, run_id)
        assert result is not None and result.collisions == 0 and 0 < result.coverage < 1
        series = s.get(MetricSeries, run_id)
        assert series is not None
        volume = np.frombuffer(series.explored_volume_m3, dtype="<f4")
        assert len(volume) == 9 and np.all(np.diff(volume) >= 0)
        artifacts = {a.kind: a for a in s.scalars(select(Artifact).where(
            Artifact.run_id == run_id))}
    assert set(artifacts) == {"recording", "mesh", "log", "result"}
    store = open_store(settings.artifacts)
    import hashlib

    for artifact in artifacts.values():
        data = store.open_path(artifact.location).read_bytes()
        assert len(data) == artifact.size_bytes
        assert hashlib.sha256(data).hexdigest() == artifact.sha256
    assert b"succeeded" in store.open_path(artifacts["log"].location).read_bytes()
    assert _count(sessions, RunResult, run_id) == 1
    # The record: in the row and in result.json, naming the version the row is filed under.
    record = result.record
    assert record is not None and record["benchmark_version"] == result.benchmark_version
    assert result.benchmark_version not in {"legacy", "unknown"}
    assert record["seed"] == 0 and record["preset"]["name"] == "default"
    assert record["planner"]["id"].startswith("classic-v") and record["planner"]["code_sha256"]
    assert record["area"]["name"] == "maze" and record["area"]["sha256"]
    assert record["machine"]["speed_factor"] == pytest.approx(machine_speed_factor())
    stored = json.loads(store.open_path(artifacts["result"].location).read_bytes())
    assert stored["reproducibility"] == record
    metrics = result.metrics
    assert metrics is not None and metrics == stored["metrics"]
    assert metrics["coverage"] == pytest.approx(result.coverage)
    assert {"explored_observable_m3", "time_to_90_coverage_s"} <= set(metrics)


def test_without_a_record_builder_the_row_keeps_what_the_worker_knows(
        sessions: sessionmaker[Session], settings: Settings) -> None:
    (run_id,) = _job(sessions, settings, seconds=4.0)
    install_record_builder(None)
    try:
        assert execute_run(run_id, settings) == "succeeded"
    finally:
        install_record_builder(reproducibility_record)
    with sessions() as s:
        result = s.get(RunResult, run_id)
        assert result is not None and result.benchmark_version == "unknown"
        assert result.record is not None and result.record["seed"] == 0
        assert result.record["planner"]["id"].startswith("classic-v")
        assert "no record builder" in result.record["missing"][0]
        assert result.metrics is not None and "coverage" in result.metrics


def test_a_failing_record_builder_does_not_fail_the_run(sessions: sessionmaker[Session],
                                                         settings: Settings) -> None:
    (run_id,) = _job(sessions, settings, seconds=4.0)

    def broken(**kwargs: Any) -> dict[str, Any]:
        raise OSError("disk gone")

    install_record_builder(broken)
    try:
        assert execute_run(run_id, settings) == "succeeded"
    finally:
        install_record_builder(reproducibility_record)
    with sessions() as s:
        result = s.get(RunResult, run_id)
        assert result is not None and result.benchmark_version == "unknown"
        assert result.record is not None and "OSError: disk gone" in result.record["missing"][0]


def test_the_soft_time_limit_in_a_plan_call_is_the_platforms(
        sessions: sessionmaker[Session], settings: Settings,
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Celery's soft time limit reaching the planner's `plan` ends the run as over its
    wall-time limit, not as a planner that raised (which would store its metrics)."""
    import planners.registry

    real_make = planners.registry.make

    def make(planner_id: str, *args: Any, **kwargs: Any) -> Any:
        planner = real_make(planner_id, *args, **kwargs)

        def plan(*_: Any, **__: Any) -> Any:
            raise SoftTimeLimitExceeded()

        planner.plan = plan
        return planner

    monkeypatch.setattr(planners.registry, "make", make)
    (run_id,) = _job(sessions, settings, seconds=12.0)  # past the 9 s start-up spin
    assert execute_run(run_id, settings) == "timed out"
    with sessions() as s:
        run = s.get(Run, run_id)
        assert run is not None and run.status == RunState.FAILED.value
        assert run.error is not None and "wall-time limit" in run.error
        assert "planner raised" not in run.error
    assert _count(sessions, RunResult, run_id) == 0


def test_the_speed_factor_is_measured_once_per_process(monkeypatch: pytest.MonkeyPatch) -> None:
    import sim.reference_speed
    from worker import speed

    calls: list[int] = []

    def measure() -> float:
        calls.append(1)
        time.sleep(0.2)
        return 0.75

    monkeypatch.setattr(speed, "_speed", [])
    monkeypatch.setattr(sim.reference_speed, "speed_factor", measure)
    thread = measure_speed_in_background()
    assert machine_speed_factor() == 0.75  # waits for the measurement under way
    thread.join(5)
    assert machine_speed_factor() == 0.75 and calls == [1]


def test_cancel_while_running(sessions: sessionmaker[Session], settings: Settings) -> None:
    (run_id,) = _job(sessions, settings, seconds=600.0)

    def cancel_soon() -> None:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            with sessions() as s:
                run = s.get(Run, run_id)
                if run is not None and run.status == "running" and run.sim_time_s > 2:
                    s.execute(update(Run).where(Run.id == run_id).values(cancel_requested=True))
                    s.commit()
                    return
            time.sleep(0.2)

    canceller = threading.Thread(target=cancel_soon)
    canceller.start()
    started = time.monotonic()
    assert execute_run(run_id, settings) == "cancelled"
    canceller.join()
    assert time.monotonic() - started < 60
    with sessions() as s:
        run = s.get(Run, run_id)
        assert run is not None and run.status == "cancelled" and run.sim_time_s < 600
    assert _count(sessions, RunResult, run_id) == 0


def test_a_queued_run_cancelled_before_a_worker_takes_it(sessions: sessionmaker[Session],
                                                         settings: Settings) -> None:
    (run_id,) = _job(sessions, settings)
    with sessions() as s:
        s.execute(update(Run).where(Run.id == run_id).values(cancel_requested=True))
        s.commit()
    assert execute_run(run_id, settings) == "skipped"
    with sessions() as s:
        assert s.get(Run, run_id).status == "cancelled"  # type: ignore[union-attr]


def test_a_live_claim_is_not_taken_but_a_dead_one_is(sessions: sessionmaker[Session],
                                                     settings: Settings) -> None:
    (run_id,) = _job(sessions, settings)
    first = claim(sessions, settings, run_id)
    assert first is not None and first.attempt == 1
    assert claim(sessions, settings, run_id) is None  # its heartbeat is fresh
    with sessions() as s:
        s.execute(update(Run).where(Run.id == run_id).values(
            heartbeat_at=utcnow() - timedelta(seconds=settings.heartbeat_timeout_s + 1)))
        s.commit()
    # The presumed-dead first attempt's work is refused; the new attempt stores its result.
    assert execute_run(run_id, settings) == "succeeded"
    with sessions() as s:
        run = s.get(Run, run_id)
        assert run is not None and run.attempts == 2 and run.claim_token != first.token
    assert _count(sessions, RunResult, run_id) == 1


def test_a_full_artifact_store_fails_the_run_cleanly(sessions: sessionmaker[Session],
                                                      settings: Settings,
                                                      tmp_path: Path) -> None:
    (run_id,) = _job(sessions, settings, seconds=4.0)
    blocker = tmp_path / "not-a-folder"
    blocker.write_text("a file where the store's folder should be")
    broken = settings.model_copy(update={"artifact_url": blocker.as_uri()})
    assert execute_run(run_id, broken) == "failed"
    with sessions() as s:
        run = s.get(Run, run_id)
        assert run is not None and run.status == RunState.FAILED.value
        assert run.failure_kind == "platform"
        assert run.error is not None and "could not store the run's artifacts" in run.error
    assert _count(sessions, RunResult, run_id) == 0
    assert _count(sessions, Artifact, run_id) == 0


def test_a_mesh_that_cannot_be_written_fails_the_run(sessions: sessionmaker[Session],
                                                      settings: Settings,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """The result folder's writer checks the mesh writer's answer (one writer for the worker
    and `flybo run`): a run whose mesh was not written stores nothing."""
    from sim.open3d_any import o3d

    (run_id,) = _job(sessions, settings, seconds=4.0)
    monkeypatch.setattr(o3d.io, "write_triangle_mesh", lambda *args, **kwargs: False)
    assert execute_run(run_id, settings) == "failed"
    with sessions() as s:
        run = s.get(Run, run_id)
        assert run is not None and run.failure_kind == "platform"
        assert run.error is not None and "could not write" in run.error and "mesh.ply" in run.error
    assert _count(sessions, RunResult, run_id) == 0
    assert _count(sessions, Artifact, run_id) == 0
