"""Load: 200 concurrent clients on loopback poll a running job's progress and the leaderboard
for 60 s (FLYBO_LOAD_SECONDS) against the embedded service while a worker flies the job.
No request may fail; throughput and latency percentiles are written to test-artifacts/."""

from __future__ import annotations

import asyncio
import json
import os
import socket
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import httpx

CLIENTS = 200
SECONDS = float(os.environ.get("FLYBO_LOAD_SECONDS", "60"))
ARTIFACTS = Path(__file__).resolve().parents[2] / "test-artifacts"


async def _client(base: str, job_id: int, until: float, latencies: list[float],
                  errors: list[str], retries: list[str], http: httpx.AsyncClient,
                  index: int) -> None:
    paths = [f"/api/v1/jobs/{job_id}", "/api/v1/leaderboard"]
    i = index
    while time.monotonic() < until:
        path = paths[i % 2]
        i += 1
        started = time.monotonic()
        for attempt in (1, 2):
            try:
                answer = await http.get(base + path)
                if answer.status_code != 200:
                    errors.append(f"{path}: {answer.status_code}")
                break
            except httpx.TransportError as exc:
                # A reused keep-alive connection that the server closed at that moment is
                # retried once, as HTTP clients do for idempotent requests; counted apart.
                if attempt == 2:
                    errors.append(f"{path}: {type(exc).__name__}")
                else:
                    retries.append(path)
        latencies.append(time.monotonic() - started)


async def _load(base: str, job_id: int) -> tuple[list[float], list[str], list[str]]:
    latencies: list[float] = []
    errors: list[str] = []
    retries: list[str] = []
    limits = httpx.Limits(max_connections=CLIENTS, max_keepalive_connections=CLIENTS)
    async with httpx.AsyncClient(limits=limits, timeout=30.0) as http:
        until = time.monotonic() + SECONDS
        await asyncio.gather(*(_client(base, job_id, until, latencies, errors, retries, http, i)
                               for i in range(CLIENTS)))
    return latencies, errors, retries


def test_two_hundred_clients_for_a_minute(tmp_path: Path) -> None:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    base = f"http://127.0.0.1:{port}"
    env = {k: v for k, v in os.environ.items() if not k.startswith("FLYBO_")}
    env["FLYBO_DATA_DIR"] = str(tmp_path / "data")
    if "FLYBO_CACHE_DIR" in os.environ:
        env["FLYBO_CACHE_DIR"] = os.environ["FLYBO_CACHE_DIR"]
    token = subprocess.run([sys.executable, "-m", "flybo", "tokens", "create", "--user", "l"],
                           env=env, capture_output=True, text=True, check=True).stdout.strip()
    log = (tmp_path / "serve.log").open("wb")
    server = subprocess.Popen([sys.executable, "-m", "flybo", "serve", "--port", str(port)],
                              env=env, stdout=log, stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + 60
        while True:
            try:
                if httpx.get(f"{base}/healthz", timeout=2).status_code == 200:
                    break
            except httpx.HTTPError:
                pass
            assert time.monotonic() < deadline
            time.sleep(0.3)
        job = httpx.post(f"{base}/api/v1/jobs", headers={"Authorization": f"Bearer {token}"},
                         json={"planner": "classic", "areas": ["maze"], "runs": 2,
                               "seconds": 700}).json()
        # A thread of its own: a test before this one in the process may have left an event
        # loop running in the main thread, where asyncio.run refuses to start.
        with ThreadPoolExecutor(1) as thread:
            latencies, errors, retries = thread.submit(asyncio.run, _load(base, job["id"])).result()
        progress = httpx.get(f"{base}/api/v1/jobs/{job['id']}").json()
    finally:
        server.terminate()
        server.wait(timeout=60)
    ordered = sorted(latencies)

    def pct(p: float) -> float:
        return 1000.0 * ordered[min(len(ordered) - 1, int(p * len(ordered)))]

    report = {"clients": CLIENTS, "seconds": SECONDS, "requests": len(latencies),
              "errors": len(errors), "retried_connections": len(retries),
              "throughput_rps": len(latencies) / SECONDS,
              "p50_ms": pct(0.50), "p95_ms": pct(0.95), "p99_ms": pct(0.99),
              "job_progress_at_end": progress["progress"]}
    ARTIFACTS.mkdir(exist_ok=True)
    (ARTIFACTS / "load.json").write_text(json.dumps(report, indent=2) + "\n")
    print(json.dumps(report))
    assert errors == [], errors[:10]
    assert len(latencies) > CLIENTS
    assert progress["progress"] > 0  # the job advanced while the clients polled
