"""The sweep requeues runs of dead workers, fails hopeless ones, and re-enqueues lost messages."""

from __future__ import annotations

from datetime import timedelta

from sqlalchemy import select, update
from sqlalchemy.orm import Session, sessionmaker

from server.catalog import sync_builtin_planners
from server.db import session_scope
from server.jobs import create_job
from server.models import Run, User, utcnow
from server.schemas import JobCreate
from server.settings import Settings
from server.sweeper import sweep


def _runs(sessions: sessionmaker[Session], settings: Settings, n: int) -> list[int]:
    with session_scope(sessions) as s:
        sync_builtin_planners(s)
        user = User(name="carol")
        s.add(user)
        s.flush()
        created = create_job(s, settings, user, JobCreate(planner="classic", areas=["maze"],
                                                          runs=n, seconds=10))
    return [run_id for run_id, _ in created.runs]


def _messages(settings: Settings) -> int:
    folder = settings.broker_folder / "queue"
    return len(list(folder.iterdir())) if folder.is_dir() else 0


def test_sweep(sessions: sessionmaker[Session], settings: Settings) -> None:
    dead, hopeless, fresh, waiting = _runs(sessions, settings, 4)
    old = utcnow() - timedelta(seconds=settings.heartbeat_timeout_s + 5)
    with sessions() as s:
        s.execute(update(Run).where(Run.id.in_([dead, hopeless, fresh])).values(
            status="running", claim_token="x", attempts=1, started_at=utcnow(),
            heartbeat_at=old))
        s.execute(update(Run).where(Run.id == hopeless).values(attempts=settings.max_attempts))
        s.execute(update(Run).where(Run.id == fresh).values(heartbeat_at=utcnow()))
        s.execute(update(Run).where(Run.id == waiting).values(
            enqueued_at=utcnow() - timedelta(seconds=settings.requeue_queued_after_s + 5)))
        s.commit()
    before = _messages(settings)
    enqueued = sweep(sessions, settings)
    assert sorted(r for r, _ in enqueued) == sorted([dead, waiting])
    assert _messages(settings) == before + 2  # on the real (filesystem) broker
    with sessions() as s:
        states = dict(s.execute(select(Run.id, Run.status)).all())
        error = s.scalar(select(Run.error).where(Run.id == hopeless))
    assert states[dead] == "queued" and states[fresh] == "running"
    assert states[hopeless] == "failed" and "stopped responding" in (error or "")
    assert sweep(sessions, settings) == []  # nothing left to do
