"""The service as users run it, in real processes.

- Embedded: `flybo serve` (API + one worker) on SQLite and the filesystem broker.
- Scale-out: the API (`flybo serve --workers 0`) and two `flybo worker` processes on the
  PostgreSQL and Redis of this machine: the topology of `docker-compose.yml`, without Docker.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import httpx

FINAL = {"succeeded", "failed", "cancelled"}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@contextmanager
def _processes(commands: list[list[str]], env: dict[str, str], logs: Path) -> Iterator[None]:
    procs = []
    try:
        for i, cmd in enumerate(commands):
            out = (logs / f"proc-{i}.log").open("wb")
            procs.append(subprocess.Popen([sys.executable, "-m", "flybo", *cmd], env=env,
                                          stdout=out, stderr=subprocess.STDOUT))
        yield
    finally:
        for proc in procs:
            proc.terminate()
        for proc in procs:
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                proc.kill()


def _env(tmp_path: Path, **extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("FLYBO_")}
    env.update({"FLYBO_DATA_DIR": str(tmp_path / "data"), **extra})
    if "FLYBO_CACHE_DIR" in os.environ:
        env["FLYBO_CACHE_DIR"] = os.environ["FLYBO_CACHE_DIR"]
    return env


def _token(env: dict[str, str], user: str) -> str:
    out = subprocess.run([sys.executable, "-m", "flybo", "tokens", "create", "--user", user],
                         env=env, capture_output=True, text=True, check=True)
    return out.stdout.strip()


def _cli(command: list[str], env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(command, env=env, capture_output=True, text=True, timeout=180)


def _wait_healthy(base: str, logs: Path, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            if httpx.get(f"{base}/healthz", timeout=2).status_code == 200:
                return
        except httpx.HTTPError:
            pass
        time.sleep(0.5)
    raise AssertionError(f"the API did not start: {_tail(logs)}")


def _tail(logs: Path) -> str:
    return "\n".join(p.read_text(errors="replace")[-3000:] for p in sorted(logs.glob("*.log")))


def _wait_job(base: str, job_id: int, logs: Path, timeout: float) -> dict[str, Any]:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        job: dict[str, Any] = httpx.get(f"{base}/api/v1/jobs/{job_id}", timeout=10).json()
        if job["status"] in FINAL:
            return job
        time.sleep(1.0)
    raise AssertionError(f"job {job_id} did not end in {timeout} s: {_tail(logs)}")


def _check_results(base: str, job: dict[str, Any], logs: Path) -> list[str]:
    assert job["status"] == "succeeded", _tail(logs)
    workers = []
    for brief in job["runs"]:
        run = httpx.get(f"{base}/api/v1/runs/{brief['id']}").json()
        assert run["result"]["collisions"] == 0 and run["result"]["coverage"] > 0
        # The worker process (`flybo worker`) recorded what made the run.
        record = run["result"]["record"]
        assert record["benchmark_version"] == run["result"]["benchmark_version"] != "unknown"
        assert record["machine"]["speed_factor"] > 0 and record["seed"] == brief["seed"]
        assert "time_to_90_coverage_s" in run["result"]["metrics"]
        assert {a["kind"] for a in run["artifacts"]} == {"recording", "mesh", "result"}
        series = httpx.get(f"{base}/api/v1/runs/{brief['id']}/series").json()
        assert len(series["explored_volume_m3"]) == int(run["seconds"]) + 1
        mesh = httpx.get(f"{base}/api/v1/runs/{brief['id']}/artifacts/mesh")
        assert mesh.status_code == 200 and mesh.content.startswith(b"ply")
        workers.append(run["worker"])
    return workers


def test_embedded_service(tmp_path: Path) -> None:
    port = _free_port()
    base = f"http://127.0.0.1:{port}"
    env = _env(tmp_path)
    logs = tmp_path / "logs"
    logs.mkdir()
    token = _token(env, "eve")
    auth = {"Authorization": f"Bearer {token}"}
    with _processes([["serve", "--port", str(port), "--workers", "1"]], env, logs):
        _wait_healthy(base, logs)
        started = time.monotonic()
        job = httpx.post(f"{base}/api/v1/jobs", headers=auth, json={
            "planner": "classic", "areas": ["maze"], "runs": 2, "seconds": 20}).json()
        job = _wait_job(base, job["id"], logs, timeout=240)
        elapsed = time.monotonic() - started
        _check_results(base, job, logs)
        board = httpx.get(f"{base}/api/v1/leaderboard").json()
        # The API's current version is the workers': the default board holds their runs.
        first = httpx.get(f"{base}/api/v1/runs/{job['runs'][0]['id']}").json()
        assert board["benchmark_version"] == first["result"]["benchmark_version"]
        entry = board["entries"][0]
        assert (entry["planner"], entry["area"], entry["runs"]) == ("classic-v3", "maze", 2)
        assert board["overall"][0]["rank"] == 1
        assert elapsed < 240

        # The command-line client against the same server.
        client = [sys.executable, "-m", "flybo"]
        shown = _cli([*client, "jobs", str(job["id"]), "--server", base], env)
        assert shown.returncode == 0 and "succeeded" in shown.stdout
        results = _cli([*client, "results", "--server", base], env)
        assert results.returncode == 0 and "classic-v3" in results.stdout
        refused = _cli([*client, "submit", "--server", base, "--token", token, "--planner",
                        "teleport", "--areas", "maze"], env)
        assert refused.returncode == 2 and "classic-v1" in refused.stderr
        no_token = _cli([*client, "submit", "--server", base, "--planner", "classic",
                         "--areas", "maze"], {**env, "FLYBO_TOKEN": ""})
        assert no_token.returncode == 2 and "token" in no_token.stderr
        waited = _cli([*client, "submit", "--server", base, "--token", token, "--planner",
                       "classic", "--areas", "maze", "--seconds", "5", "--wait"], env)
        assert waited.returncode == 0 and "succeeded" in waited.stdout, waited.stderr

        # Cancel while running: the run stops within seconds, and the job ends cancelled.
        long = httpx.post(f"{base}/api/v1/jobs", headers=auth, json={
            "planner": "classic", "areas": ["maze"], "runs": 1, "seconds": 700}).json()
        run_id = long["runs"][0]["id"]
        deadline = time.monotonic() + 120
        while httpx.get(f"{base}/api/v1/runs/{run_id}").json()["sim_time_s"] <= 0:
            assert time.monotonic() < deadline, _tail(logs)
            time.sleep(0.5)
        asked = time.monotonic()
        httpx.post(f"{base}/api/v1/jobs/{long['id']}/cancel", headers=auth)
        cancelled = _wait_job(base, long["id"], logs, timeout=60)
        assert cancelled["status"] == "cancelled"
        assert time.monotonic() - asked < 30
        assert httpx.get(f"{base}/api/v1/runs/{run_id}").json()["sim_time_s"] < 700


def test_scale_out_on_postgres_and_redis(tmp_path: Path, fresh_postgres_url: str,
                                         redis_url: str) -> None:
    port = _free_port()
    base = f"http://127.0.0.1:{port}"
    env = _env(tmp_path, FLYBO_DATABASE_URL=fresh_postgres_url, FLYBO_BROKER_URL=redis_url)
    logs = tmp_path / "logs"
    logs.mkdir()
    token = _token(env, "frank")
    commands = [["serve", "--port", str(port), "--workers", "0"], ["worker"], ["worker"]]
    with _processes(commands, env, logs):
        _wait_healthy(base, logs)
        deadline = time.monotonic() + 60
        while _tail(logs).count(" ready.") < 2:  # both workers listen before the job exists
            assert time.monotonic() < deadline, _tail(logs)
            time.sleep(0.5)
        job = httpx.post(f"{base}/api/v1/jobs", headers={"Authorization": f"Bearer {token}"},
                         json={"planner": "classic", "areas": ["maze"], "runs": 4,
                               "seconds": 15}).json()
        job = _wait_job(base, job["id"], logs, timeout=240)
        workers = _check_results(base, job, logs)
    assert len(set(workers)) == 2, workers  # both worker processes took runs
