"""A run's claim: who flies it, and the writes only the claim's holder may make.

A conditional UPDATE moves the run from `queued` (or `running` with a dead worker) to `running`
with a fresh claim token; a duplicate message finds nothing to claim. The final state, and the
log tail, are written only while the token still matches, so an attempt that lost its claim
(its worker was presumed dead) stores nothing.
"""

from __future__ import annotations

import logging
import os
import secrets
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass
from datetime import timedelta

from sqlalchemy import Engine, or_, select, update
from sqlalchemy.orm import Session, sessionmaker

from server.db import make_engine, make_session_factory
from server.models import Base, FailureKind, Run, RunState, utcnow
from server.settings import Settings

log = logging.getLogger(__name__)

_engines: dict[tuple[int, str], tuple[Engine, sessionmaker[Session]]] = {}


def sessions_for(settings: Settings) -> sessionmaker[Session]:
    """One engine per process and URL (created after a fork, never inherited)."""
    key = (os.getpid(), settings.db_url)
    if key not in _engines:
        engine = make_engine(settings.db_url)
        _engines[key] = (engine, make_session_factory(engine))
    return _engines[key][1]


def worker_name() -> str:
    return f"{socket.gethostname()}-{os.getpid()}"


@dataclass(frozen=True)
class Claim:
    run_id: int
    token: str
    attempt: int


def claim(factory: sessionmaker[Session], settings: Settings, run_id: int) -> Claim | None:
    """Take the run if nobody live holds it; None if it is final, held, or cancelled."""
    token = secrets.token_hex(16)
    now = utcnow()
    stale = now - timedelta(seconds=settings.heartbeat_timeout_s)
    with factory() as session:
        result = session.execute(
            update(Run).where(
                Run.id == run_id, Run.cancel_requested.is_(False),
                or_(Run.status == RunState.QUEUED.value,
                    (Run.status == RunState.RUNNING.value) & (Run.heartbeat_at < stale)))
            .values(status=RunState.RUNNING.value, claim_token=token,
                    attempts=Run.attempts + 1, worker=worker_name(), started_at=now,
                    heartbeat_at=now, progress=0.0, sim_time_s=0.0)
        )
        if not getattr(result, "rowcount", 0):
            # A queued run whose cancellation came first ends here.
            session.execute(update(Run).where(
                Run.id == run_id, Run.status == RunState.QUEUED.value,
                Run.cancel_requested.is_(True)).values(status=RunState.CANCELLED.value,
                                                       finished_at=now))
            session.commit()
            return None
        attempts = session.scalar(select(Run.attempts).where(Run.id == run_id)) or 1
        session.commit()
    return Claim(run_id, token, attempts)


def save_tail(factory: sessionmaker[Session], held: Claim, tail: str) -> None:
    """The last log lines, kept with the run whatever its end (only by the claim's holder)."""
    try:
        with factory() as session:
            session.execute(update(Run).where(Run.id == held.run_id,
                                              Run.claim_token == held.token).values(log_tail=tail))
            session.commit()
    except Exception as exc:  # the full log is in the artifact store when it could be stored
        log.warning("could not save the log tail of run %s: %s", held.run_id, exc)


def finish(factory: sessionmaker[Session], held: Claim, state: RunState, wall0: float, *,
           kind: FailureKind | None = None, error: str | None = None,
           rows: Callable[[], list[Base]] | None = None) -> bool:
    """Set the final state (with the result rows) if this attempt still holds the run."""
    with factory() as session:
        changed = session.execute(update(Run).where(
            Run.id == held.run_id, Run.claim_token == held.token,
            Run.status == RunState.RUNNING.value).values(
            status=state.value, finished_at=utcnow(), progress=1.0, error=error,
            failure_kind=kind.value if kind else None,
            wall_time_s=time.monotonic() - wall0))
        if not getattr(changed, "rowcount", 0):
            session.rollback()
            return False
        if rows is not None:
            session.add_all(rows())
        session.commit()
    return True
