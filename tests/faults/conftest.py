"""A real scale-out stack for fault tests: the API and worker processes on this machine's
PostgreSQL and Redis, with short heartbeat and sweep periods so that recoveries take seconds.

Under CI=true an unreachable PostgreSQL or Redis fails these tests; elsewhere they skip.
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

POSTGRES_ADMIN_URL = os.environ.get("FLYBO_TEST_POSTGRES_URL",
                                    "postgresql+psycopg://postgres@127.0.0.1:5432/test")
REDIS_URL = os.environ.get("FLYBO_TEST_REDIS_URL", "redis://127.0.0.1:6379/14")
FINAL = {"succeeded", "failed", "cancelled"}


def _unavailable(what: str, why: str) -> None:
    message = f"{what} is not reachable ({why})"
    if os.environ.get("CI") == "true":
        pytest.fail(message + "; under CI=true it must be")
    pytest.skip(message + "; set CI=true to make this a failure")


class Stack:
    """API + workers as subprocesses, each in its own process group."""

    def __init__(self, tmp: Path, db_url: str) -> None:
        self.db_url = db_url
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            self.port = int(s.getsockname()[1])
        self.base = f"http://127.0.0.1:{self.port}"
        self.logs = tmp / "logs"
        self.logs.mkdir()
        self.env = {k: v for k, v in os.environ.items() if not k.startswith("FLYBO_")}
        self.env.update({
            "FLYBO_DATA_DIR": str(tmp / "data"), "FLYBO_DATABASE_URL": db_url,
            "FLYBO_BROKER_URL": REDIS_URL, "FLYBO_HEARTBEAT_INTERVAL_S": "1",
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


@pytest.fixture
def database(tmp_path: Path) -> Iterator[str]:
    name = f"flybo_fault_{uuid.uuid4().hex[:8]}"
    try:
        admin = create_engine(POSTGRES_ADMIN_URL, isolation_level="AUTOCOMMIT")
        with admin.connect() as conn:
            conn.execute(text(f'CREATE DATABASE "{name}"'))
    except Exception as exc:
        _unavailable("PostgreSQL", str(exc).splitlines()[0])
    import redis

    try:
        redis.Redis.from_url(REDIS_URL, socket_connect_timeout=2).flushdb()
    except Exception as exc:
        _unavailable("Redis", str(exc).splitlines()[0])
    yield admin.url.set(database=name).render_as_string(hide_password=False)
    for _ in range(5):
        try:
            with admin.connect() as conn:
                conn.execute(text("SELECT pg_terminate_backend(pid) FROM pg_stat_activity "
                                  f"WHERE datname = '{name}'"))
                conn.execute(text(f'DROP DATABASE IF EXISTS "{name}"'))
            break
        except Exception:  # PostgreSQL may still be restarting after a test
            time.sleep(2)
    admin.dispose()


@pytest.fixture
def stack(tmp_path: Path, database: str) -> Iterator[Stack]:
    s = Stack(tmp_path, database)
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
