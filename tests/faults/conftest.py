"""A real scale-out stack for fault tests: the API and worker processes on PostgreSQL and Redis
servers of these tests' own (`servers.py`: the tests restart them), with short heartbeat and sweep
periods so that recoveries take seconds.

Under CI=true a PostgreSQL or Redis that cannot be started fails these tests; elsewhere they skip.
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import time
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from sqlalchemy import create_engine, text

from tests.faults.servers import PostgresServer, RedisServer

FINAL = {"succeeded", "failed", "cancelled"}


def _unavailable(what: str, why: str) -> None:
    message = f"{what} is not available ({why})"
    if os.environ.get("CI") == "true":
        pytest.fail(message + "; under CI=true it must be")
    pytest.skip(message + "; set CI=true to make this a failure")


class Stack:
    """API + workers as subprocesses, each in its own process group."""

    def __init__(self, tmp: Path, db_url: str, servers: Servers) -> None:
        self.db_url = db_url
        self.servers = servers
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            self.port = int(s.getsockname()[1])
        self.base = f"http://127.0.0.1:{self.port}"
        self.logs = tmp / "logs"
        self.logs.mkdir()
        self.env = {k: v for k, v in os.environ.items() if not k.startswith("FLYBO_")}
        self.env.update({
            "FLYBO_DATA_DIR": str(tmp / "data"), "FLYBO_DATABASE_URL": db_url,
            "FLYBO_BROKER_URL": servers.redis.url, "FLYBO_HEARTBEAT_INTERVAL_S": "1",
            "FLYBO_HEARTBEAT_TIMEOUT_S": "6", "FLYBO_SWEEP_INTERVAL_S": "2",
            "FLYBO_REQUEUE_QUEUED_AFTER_S": "8", "FLYBO_MAX_ATTEMPTS": "10",
        })
        if "FLYBO_CACHE_DIR" in os.environ:
            self.env["FLYBO_CACHE_DIR"] = os.environ["FLYBO_CACHE_DIR"]
        self.api: subprocess.Popen[bytes] | None = None
        self.workers: list[subprocess.Popen[bytes]] = []
        self._n = 0
        self.token = subprocess.run(
            [sys.executable, "-m", "flybo", "tokens", "create", "--user", "ops", "--admin"],
            env=self.env, capture_output=True, text=True, check=True).stdout.strip()

    def _spawn(self, *args: str) -> subprocess.Popen[bytes]:
        self._n += 1
        out = (self.logs / f"{self._n:02d}-{args[0]}.log").open("wb")
        return subprocess.Popen([sys.executable, "-m", "flybo", *args], env=self.env,
                                stdout=out, stderr=subprocess.STDOUT, start_new_session=True)

    def start_api(self) -> None:
        self.api = self._spawn("serve", "--port", str(self.port), "--workers", "0")
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            try:
                if httpx.get(f"{self.base}/healthz", timeout=2).status_code == 200:
                    return
            except httpx.HTTPError:
                pass
            time.sleep(0.3)
        raise AssertionError("API did not start:\n" + self.tail())

    def start_worker(self) -> subprocess.Popen[bytes]:
        proc = self._spawn("worker")
        self.workers.append(proc)
        return proc

    def kill(self, proc: subprocess.Popen[bytes], sig: int = signal.SIGKILL) -> None:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, sig)
        proc.wait(timeout=30)

    def submit(self, **body: Any) -> dict[str, Any]:
        answer = httpx.post(f"{self.base}/api/v1/jobs", json=body, timeout=30,
                            headers={"Authorization": f"Bearer {self.token}"})
        assert answer.status_code == 201, answer.text
        job: dict[str, Any] = answer.json()
        return job

    def get(self, path: str) -> Any:
        for _ in range(60):  # the API may be restarting
            try:
                answer = httpx.get(f"{self.base}/api/v1{path}", timeout=10)
                if answer.status_code < 500:
                    return answer.json()
            except httpx.HTTPError:
                pass
            time.sleep(1.0)
        raise AssertionError(f"GET {path} kept failing:\n{self.tail()}")

    def wait_job(self, job_id: int, timeout: float) -> dict[str, Any]:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            job: dict[str, Any] = self.get(f"/jobs/{job_id}")
            if job["status"] in FINAL:
                return job
            time.sleep(1.0)
        raise AssertionError(f"job {job_id} did not end in {timeout} s:\n{self.tail()}")

    def tail(self) -> str:
        return "\n".join(f"--- {p.name}\n" + p.read_text(errors="replace")[-2500:]
                         for p in sorted(self.logs.glob("*.log")))

    def count(self, sql: str) -> int:
        return count_rows(self.db_url, sql)

    def stop(self) -> None:
        for proc in [*self.workers, *([self.api] if self.api else [])]:
            if proc.poll() is None:
                self.kill(proc, signal.SIGTERM)


class Servers:
    """The session's own PostgreSQL and Redis."""

    def __init__(self, postgres: PostgresServer, redis: RedisServer) -> None:
        self.postgres = postgres
        self.redis = redis


@pytest.fixture(scope="session")
def servers() -> Iterator[Servers]:
    postgres: PostgresServer | None = None
    redis: RedisServer | None = None
    try:
        try:
            postgres = PostgresServer()
        except (OSError, subprocess.SubprocessError, AssertionError) as exc:
            _unavailable("PostgreSQL", str(exc).splitlines()[0])
        try:
            redis = RedisServer()
        except (OSError, subprocess.SubprocessError, AssertionError) as exc:
            _unavailable("Redis", str(exc).splitlines()[0])
        assert postgres is not None and redis is not None
        yield Servers(postgres, redis)
    finally:
        if redis is not None:
            redis.stop()
        if postgres is not None:
            postgres.stop()


@pytest.fixture
def database(servers: Servers) -> Iterator[str]:
    """A fresh database on the session's PostgreSQL, and an empty Redis."""
    import redis

    name = f"flybo_fault_{uuid.uuid4().hex[:8]}"
    admin = create_engine(servers.postgres.admin_url, isolation_level="AUTOCOMMIT")
    with admin.connect() as conn:
        conn.execute(text(f'CREATE DATABASE "{name}"'))
    redis.Redis.from_url(servers.redis.url, socket_connect_timeout=2).flushdb()
    yield admin.url.set(database=name).render_as_string(hide_password=False)
    admin.dispose()  # its connection did not outlive a restart of the server
    with admin.connect() as conn:
        conn.execute(text("SELECT pg_terminate_backend(pid) FROM pg_stat_activity "
                          f"WHERE datname = '{name}'"))
        conn.execute(text(f'DROP DATABASE IF EXISTS "{name}"'))
    admin.dispose()


@pytest.fixture
def stack(tmp_path: Path, database: str, servers: Servers) -> Iterator[Stack]:
    s = Stack(tmp_path, database, servers)
    try:
        yield s
    finally:
        s.stop()


def count_rows(db_url: str, sql: str) -> int:
    engine = create_engine(db_url)
    with engine.connect() as conn:
        value = conn.execute(text(sql)).scalar()
    engine.dispose()
    return int(value or 0)
