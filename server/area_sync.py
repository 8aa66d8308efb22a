"""The built-in areas' rows, written at the API's start-up by a process of its own
(`python -m server.area_sync`, the database URL on its stdin), at low CPU priority.

Building an area is seconds of numpy and Python, eleven times over where the area cache is
empty. In a thread of the API process it held the GIL for stretches of up to a second, and
`/healthz` and every other request waited behind it (`docs/sandbox.md`,
`benchmarks/healthz_under_uploads.py`). In its own process the API only waits for it. The URL
goes through stdin, not the command line, which every user of the machine can read.

Several API processes on one host (`flybo serve --api-workers N`) start together: the first to
take the host's lock for the database builds the rows, the others leave it to that one.
"""

from __future__ import annotations

import fcntl
import hashlib
import logging
import os
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from sqlalchemy.orm import Session, sessionmaker

from areas.cache import cache_dir
from server.catalog import sync_builtin_areas
from server.db import make_engine, make_session_factory

log = logging.getLogger(__name__)
# Below the API, the upload checks and the runs: the rows are needed only by the area pages and
# new jobs, which build a missing row themselves (`catalog.ensure_area`).
NICENESS = 10


def sync_areas(db_url: str, sessions: sessionmaker[Session]) -> None:
    """Write the built-in areas' rows to `db_url` from a process of their own, and wait for
    it; a failure is logged. An in-memory database, which another process cannot reach, is
    synced in this process through `sessions`."""
    if db_url.startswith("sqlite") and (":memory:" in db_url or db_url.endswith("://")):
        sync_builtin_areas(sessions)
        return
    done = subprocess.run([sys.executable, "-m", "server.area_sync"], input=db_url + "\n",
                          capture_output=True, text=True)
    if done.returncode != 0:
        log.error("syncing the built-in areas failed (exit code %d): %s", done.returncode,
                  done.stderr.strip()[-2000:])


def lock_path(db_url: str) -> Path:
    """The file whose lock one process on this host holds while it syncs `db_url`."""
    digest = hashlib.sha256(db_url.encode()).hexdigest()[:16]
    return cache_dir() / "locks" / f"area-sync-{digest}.lock"


@contextmanager
def sync_lock(db_url: str) -> Iterator[bool]:
    """Whether this process got the host's lock for syncing `db_url` (held until the end)."""
    path = lock_path(db_url)
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("a") as handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            yield False
            return
        try:
            yield True
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def main() -> None:
    """Read the database URL from stdin and write the built-in areas' rows there, unless
    another process on this host is doing so."""
    os.nice(NICENESS)
    db_url = sys.stdin.readline().strip()
    with sync_lock(db_url) as mine:
        if not mine:
            return
        engine = make_engine(db_url)
        try:
            sync_builtin_areas(make_session_factory(engine))
        finally:
            engine.dispose()


if __name__ == "__main__":
    main()
