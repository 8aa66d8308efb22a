"""While a run flies: its own log, and a thread that writes progress, the log tail and a
heartbeat every few seconds and reads cancellation. The simulation thread never waits on the
database; it learns from the heartbeat that it must stop (`RunAbortedError`)."""

from __future__ import annotations

import collections
import logging
import threading
from pathlib import Path

from sqlalchemy import select, update
from sqlalchemy.orm import Session, sessionmaker

from server.models import Run, RunState, utcnow
from server.settings import Settings
from worker.claims import Claim

log = logging.getLogger(__name__)
LOG_TAIL_LINES = 60


class RunAbortedError(Exception):
    """Raised from the progress callback to stop the simulation."""

    def __init__(self, why: str) -> None:
        super().__init__(why)
        self.why = why


class RunLog(logging.Handler):
    """The run's own log: every line to a file, the last ones kept for the live tail."""

    def __init__(self, path: Path) -> None:
        super().__init__(logging.INFO)
        self.path = path
        self.file = path.open("a", encoding="utf-8")
        self.tail: collections.deque[str] = collections.deque(maxlen=LOG_TAIL_LINES)
        self.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
        self.lock_tail = threading.Lock()

    def emit(self, record: logging.LogRecord) -> None:
        line = self.format(record)
        self.file.write(line + "\n")
        self.file.flush()
        with self.lock_tail:
            self.tail.append(line)

    def tail_text(self) -> str:
        with self.lock_tail:
            return "\n".join(self.tail)

    def close(self) -> None:
        self.file.close()
        super().close()


class Heartbeat(threading.Thread):
    """Writes progress and liveness; learns about cancellation and a lost claim."""

    def __init__(self, factory: sessionmaker[Session], settings: Settings, held: Claim,
                 run_log: RunLog, sim_seconds: float) -> None:
        super().__init__(name=f"heartbeat-{held.run_id}", daemon=True)
        self.factory, self.settings, self.held, self.run_log = factory, settings, held, run_log
        self.sim_seconds = sim_seconds
        self.sim_time = 0.0
        self.cancelled = threading.Event()
        self.lost = threading.Event()
        self.stop = threading.Event()

    def run(self) -> None:
        while not self.stop.wait(self.settings.heartbeat_interval_s):
            try:
                self.beat()
            except Exception as exc:  # the database is away: keep flying, try again
                log.warning("heartbeat of run %s failed: %s", self.held.run_id, exc)

    def beat(self) -> None:
        with self.factory() as session:
            result = session.execute(update(Run).where(
                Run.id == self.held.run_id, Run.claim_token == self.held.token,
                Run.status == RunState.RUNNING.value).values(
                heartbeat_at=utcnow(), sim_time_s=self.sim_time,
                progress=min(self.sim_time / max(self.sim_seconds, 1e-9), 0.999),
                log_tail=self.run_log.tail_text()))
            cancel = session.scalar(select(Run.cancel_requested).where(
                Run.id == self.held.run_id))
            session.commit()
        if not getattr(result, "rowcount", 0):
            self.lost.set()
        if cancel:
            self.cancelled.set()
