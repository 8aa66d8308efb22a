"""PostgreSQL and Redis servers of the fault tests' own, on free loopback ports.

The fault tests stop and restart these servers; on the machine's shared servers the restarts
would break whatever other tests run beside them at that moment.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import socket
import subprocess
import tempfile
from pathlib import Path

from tests.multihost.services import pg_tool, port_open, wait_until


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])



class PostgresServer:
    """A fresh cluster (initdb, trust auth) on 127.0.0.1, run as the `postgres` user."""

    def __init__(self) -> None:
        self.port = free_port()
        # A folder the postgres user may enter (pytest's are private to root).
        self.folder = Path(tempfile.mkdtemp(prefix="flybo-faults-pg-"))
        shutil.chown(self.folder, "postgres", "postgres")
        self.data = self.folder / "data"
        subprocess.run(["runuser", "-u", "postgres", "--", pg_tool("initdb"), "-D",
                        str(self.data), "--auth=trust", "-U", "postgres"],
                       check=True, capture_output=True, timeout=120)
        self.log = self.folder / "server.log"
        self.start()
        self.admin_url = f"postgresql+psycopg://postgres@127.0.0.1:{self.port}/postgres"

    def start(self) -> None:
        # The log file keeps the server off pg_ctl's output pipe, which would never close.
        self._pg_ctl("start", "-w", "-l", str(self.log), "-o",
                     f"-p {self.port} -k {self.folder} -c listen_addresses=127.0.0.1 "
                     "-c fsync=off")

    def _pg_ctl(self, *args: str) -> None:
        subprocess.run(["runuser", "-u", "postgres", "--", pg_tool("pg_ctl"), "-D",
                        str(self.data), *args], check=True, capture_output=True, timeout=120,
                       env={"PATH": os.environ.get("PATH", "/usr/bin:/bin")})

    def restart(self) -> None:
        """A fast shutdown (clients are disconnected), then a start; returns once it answers."""
        self._pg_ctl("stop", "-w", "-m", "fast")
        self.start()
        wait_until(lambda: port_open("127.0.0.1", self.port), "PostgreSQL")

    def stop(self) -> None:
        with contextlib.suppress(subprocess.CalledProcessError):  # it was not running
            self._pg_ctl("stop", "-m", "immediate")
        shutil.rmtree(self.folder, ignore_errors=True)


class RedisServer:
    """A Redis server that keeps nothing on disk, as the deployment's does not."""

    def __init__(self) -> None:
        self.port = free_port()
        self.folder = Path(tempfile.mkdtemp(prefix="flybo-faults-redis-"))
        self.url = f"redis://127.0.0.1:{self.port}/0"
        self.start()

    def start(self) -> None:
        subprocess.run(["redis-server", "--daemonize", "yes", "--bind", "127.0.0.1",
                        "--port", str(self.port), "--save", "", "--appendonly", "no",
                        "--dir", str(self.folder), "--logfile", str(self.folder / "redis.log"),
                        "--pidfile", str(self.folder / "redis.pid")],
                       check=True, capture_output=True, timeout=30)
        wait_until(lambda: port_open("127.0.0.1", self.port), "Redis")

    def shutdown(self) -> None:
        subprocess.run(["redis-cli", "-p", str(self.port), "shutdown", "nosave"],
                       capture_output=True, timeout=30)
        wait_until(lambda: not port_open("127.0.0.1", self.port), "the end of Redis")

    def stop(self) -> None:
        self.shutdown()
        shutil.rmtree(self.folder, ignore_errors=True)
