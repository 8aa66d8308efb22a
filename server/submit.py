"""Storing a submission (a job, a job group, a re-run) in one transaction, then enqueueing its
runs: the same steps for every route that creates runs.

The create function works inside the request's session (`server.jobs.create_job`,
`server.groups.create_group`); this module commits, turns a refusal into its HTTP answer, and
enqueues only after the commit, so a worker never sees a run that is not stored yet.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol, TypeVar

from fastapi import HTTPException, Response
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from server.jobs import JobError
from server.queue import enqueue_run
from server.settings import Settings


class Submission(Protocol):
    """What a create function returns: the runs to enqueue, and whether an earlier request with
    the same Idempotency-Key made it."""

    @property
    def runs(self) -> list[tuple[int, float]]: ...  # (run id, simulated seconds)

    @property
    def replayed(self) -> bool: ...


S = TypeVar("S", bound=Submission)


def submit(session: Session, settings: Settings, create: Callable[[], S], *,
           idempotency_key: str | None = None, response: Response | None = None) -> S:
    """`create()` committed, its runs enqueued. A `JobError` rolls back and answers with its
    status and message. `create` is called again after a lost Idempotency-Key race, to answer
    with what the winning request stored; a replay is marked on `response`."""
    try:
        created = create()
        session.commit()
    except JobError as exc:
        session.rollback()
        raise HTTPException(exc.status, str(exc)) from None
    except IntegrityError:
        # Two requests with one Idempotency-Key raced: the other one won; answer with its rows.
        session.rollback()
        if idempotency_key is None:
            raise
        try:
            created = create()
        except JobError as exc:
            raise HTTPException(exc.status, str(exc)) from None
    if created.replayed and response is not None:
        response.headers["Idempotent-Replayed"] = "true"
    enqueue_runs(settings, created.runs)
    return created


def enqueue_runs(settings: Settings, runs: list[tuple[int, float]]) -> None:
    """Send (run id, simulated seconds) to the broker, after the commit: a worker must find the
    run rows. A run the broker did not take stays queued and the sweeper sends it again."""
    for run_id, seconds in runs:
        try:
            enqueue_run(settings, run_id, seconds)
        except Exception:  # broker down: the sweeper re-enqueues queued runs
            break
