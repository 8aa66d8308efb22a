"""The periodic sweep that keeps runs moving when workers or the broker fail.

- A running run whose worker stopped sending heartbeats goes back to the queue (or fails after
  `max_attempts` attempts).
- A running run past its hard wall-time limit fails.
- A queued run that no worker took for a while is enqueued again (the first message may have
  been lost with a broker restart); the task's claim makes duplicates harmless.
Every change is a conditional UPDATE, so several API processes may sweep at once.
"""

from __future__ import annotations

import logging
from datetime import timedelta

from sqlalchemy import select, update
from sqlalchemy.orm import Session, sessionmaker

from server.models import FailureKind, Run, RunState, utcnow
from server.queue import enqueue_run
from server.settings import Settings

log = logging.getLogger(__name__)


def sweep(factory: sessionmaker[Session], settings: Settings) -> list[tuple[int, float]]:
    """One pass; returns the ids of the runs it enqueued."""
    now = utcnow()
    to_enqueue: list[tuple[int, float]] = []
    with factory() as session:
        stale = now - timedelta(seconds=settings.heartbeat_timeout_s)
        lost = session.execute(
            select(Run.id, Run.attempts, Run.claim_token, Run.seconds).where(
                Run.status == RunState.RUNNING.value, Run.heartbeat_at < stale)
        ).all()
        for run_id, attempts, token, seconds in lost:
            cond = (Run.id == run_id, Run.status == RunState.RUNNING.value,
                    Run.claim_token == token)
            if attempts >= settings.max_attempts:
                values = {"status": RunState.FAILED.value, "finished_at": now,
                          "failure_kind": FailureKind.PLATFORM.value, "claim_token": None,
                          "error": f"its worker stopped responding {attempts} times"}
            else:
                values = {"status": RunState.QUEUED.value, "claim_token": None,
                          "worker": None, "enqueued_at": now}
            if _changed(session.execute(update(Run).where(*cond).values(**values))):
                log.warning("run %s lost its worker (attempt %s): %s", run_id, attempts,
                            values["status"])
                if values["status"] == RunState.QUEUED.value:
                    to_enqueue.append((run_id, seconds))
        for run in session.scalars(select(Run).where(Run.status == RunState.RUNNING.value)):
            if run.started_at is None:
                continue
            limit = settings.run_time_limit_s(run.seconds) + 2 * settings.heartbeat_timeout_s
            if run.started_at + timedelta(seconds=limit) < now:
                session.execute(update(Run).where(
                    Run.id == run.id, Run.status == RunState.RUNNING.value,
                    Run.claim_token == run.claim_token).values(
                    status=RunState.FAILED.value, finished_at=now, claim_token=None,
                    failure_kind=FailureKind.PLANNER.value,
                    error=f"exceeded its wall-time limit of {limit:.0f} s"))
        waiting = now - timedelta(seconds=settings.requeue_queued_after_s)
        for run_id, seconds in session.execute(select(Run.id, Run.seconds).where(
                Run.status == RunState.QUEUED.value, Run.enqueued_at < waiting)):
            if _changed(session.execute(update(Run).where(
                    Run.id == run_id, Run.status == RunState.QUEUED.value).values(
                    enqueued_at=now))):
                to_enqueue.append((run_id, seconds))
        session.commit()
    for run_id, seconds in to_enqueue:
        try:
            enqueue_run(settings, run_id, seconds)
        except Exception as exc:  # the broker is down; the next sweep tries again
            log.warning("could not enqueue run %s: %s", run_id, exc)
            break
    return to_enqueue


def _changed(result: object) -> bool:
    """Whether an UPDATE matched a row (its CursorResult's rowcount)."""
    return bool(getattr(result, "rowcount", 0))
