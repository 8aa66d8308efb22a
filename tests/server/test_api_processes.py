"""Several API processes on one database and one Redis: `flybo serve --api-workers N`, and two
separate `flybo serve` processes, enforce one rate limit per client between them. Real
processes, the real Redis server (fails under CI=true when it does not answer)."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import httpx
import pytest

pytestmark = pytest.mark.slow

BURST = 4  # then one request per 100 minutes: none refills while a test runs


def _env(tmp: Path, redis_url: str | None) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("FLYBO_")}
    env.update(FLYBO_DATA_DIR=str(tmp / "data"), FLYBO_RATE_LIMIT_WRITES_PER_MINUTE="0.01",
               FLYBO_RATE_LIMIT_BURST=str(BURST))
    if "FLYBO_CACHE_DIR" in os.environ:
        env["FLYBO_CACHE_DIR"] = os.environ["FLYBO_CACHE_DIR"]
    if redis_url is not None:
        env["FLYBO_REDIS_URL"] = redis_url
    return env


def _port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@contextmanager
def _serving(env: dict[str, str], log: Path, *extra: str) -> Iterator[tuple[str, int]]:
    port = _port()
    with log.open("wb") as out:
        proc = subprocess.Popen([sys.executable, "-m", "flybo", "serve", "--port", str(port),
                                 "--workers", "0", "--no-viewer", *extra],
                                env=env, stdout=out, stderr=subprocess.STDOUT)
    base = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 120
        while True:
            assert proc.poll() is None, log.read_text(errors="replace")[-3000:]
            try:
                if httpx.get(f"{base}/healthz", timeout=2).status_code == 200:
                    break
            except httpx.HTTPError:
                pass
            assert time.monotonic() < deadline, "flybo serve did not answer within 120 s"
            time.sleep(0.3)
        yield base, proc.pid
    finally:
        proc.terminate()
        proc.wait(timeout=60)


def _token(env: dict[str, str]) -> str:
    return subprocess.run([sys.executable, "-m", "flybo", "tokens", "create", "--user", "rl"],
                          env=env, capture_output=True, text=True, check=True).stdout.strip()


def _write(base: str, token: str) -> int:
    """A request that changes data (a job without a body: 422, nothing stored) on a fresh
    connection, so that with several API processes the kernel may hand it to any of them."""
    with httpx.Client(timeout=10) as http:
        return http.post(f"{base}/api/v1/jobs", json={},
                         headers={"Authorization": f"Bearer {token}"}).status_code


def _children(pid: int) -> list[int]:
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(stat[1]) == pid:
                found.append(int(entry.name))
    return found


def test_two_serve_processes_share_one_rate_limit(tmp_path: Path, redis_url: str) -> None:
    env = _env(tmp_path, redis_url)
    token = _token(env)
    with _serving(env, tmp_path / "a.log") as (first, _), \
            _serving(env, tmp_path / "b.log") as (second, _):
        codes = [_write(first if i % 2 == 0 else second, token) for i in range(2 * BURST)]
    assert codes[:BURST] == [422] * BURST
    assert codes[BURST:] == [429] * BURST  # each process alone would have allowed 4 more


def test_api_workers_run_as_processes_with_one_limit(tmp_path: Path, redis_url: str) -> None:
    env = _env(tmp_path, redis_url)
    token = _token(env)
    with _serving(env, tmp_path / "serve.log", "--api-workers", "2") as (base, pid):
        # uvicorn's supervisor and its two API processes (besides multiprocessing's tracker).
        deadline = time.monotonic() + 60
        while len(_children(pid)) < 3 and time.monotonic() < deadline:
            time.sleep(0.5)
        assert len(_children(pid)) >= 3, _children(pid)
        codes = [_write(base, token) for _ in range(3 * BURST)]
        board = httpx.get(f"{base}/api/v1/leaderboard", timeout=10)
    assert codes[:BURST] == [422] * BURST
    assert codes[BURST:] == [429] * (2 * BURST)
    assert board.status_code == 200
    log = (tmp_path / "serve.log").read_text(errors="replace")
    assert "2 API process(es)" in log
    assert log.count("Application startup complete") == 2


def test_more_api_processes_without_redis_are_refused(tmp_path: Path) -> None:
    env = _env(tmp_path, None)
    done = subprocess.run([sys.executable, "-m", "flybo", "serve", "--api-workers", "2",
                           "--workers", "0", "--no-viewer", "--port", str(_port())],
                          env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode != 0
    assert "--api-workers 2 needs Redis" in done.stderr
