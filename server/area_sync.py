"""The built-in areas' rows, written at the API's start-up by a process of its own
(`python -m server.area_sync`, the database URL on its stdin), at low CPU priority.

Building an area is seconds of numpy and Python, eleven times over where the area cache is
empty. In a thread of the API process it held the GIL for stretches of up to a second, and
`/healthz` and every other request waited behind it (`docs/sandbox.md`,
`benchmarks/healthz_under_uploads.py`). In its own process the API only waits for it. The URL
goes through stdin, not the command line, which every user of the machine can read.
"""

from __future__ import annotations

import logging
import os
import subprocess
import sys

from sqlalchemy.orm import Session, sessionmaker

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


def main() -> None:
    """Read the database URL from stdin and write the built-in areas' rows there."""
    os.nice(NICENESS)
    engine = make_engine(sys.stdin.readline().strip())
    try:
        sync_builtin_areas(make_session_factory(engine))
    finally:
        engine.dispose()


if __name__ == "__main__":
    main()
