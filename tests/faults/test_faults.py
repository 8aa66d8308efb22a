"""Faults on the real scale-out stack: killed workers, restarted Redis, PostgreSQL and API.

Each test checks that the job completes, every run ends with exactly one result, and final
states do not change.
"""

from __future__ import annotations

import os
import signal
import time
from typing import Any

Stack = Any  # tests/faults/conftest.py: API and worker processes on PostgreSQL and Redis


def _exactly_one_result_each(stack: Stack, job: dict[str, Any]) -> None:
    if job["status"] != "succeeded":
        runs = [stack.get(f"/runs/{r['id']}") for r in job["runs"]]
        ended = [(r["id"], r["status"], r["attempts"], r.get("error")) for r in runs
                 if r["status"] != "succeeded"]
        raise AssertionError(f"job {job['id']} {job['status']}: {ended}\n{stack.tail()}")
    ids = ",".join(str(r["id"]) for r in job["runs"])
    assert stack.count(f"SELECT count(*) FROM run_results WHERE run_id IN ({ids})") \
        == len(job["runs"])
    assert stack.count("SELECT count(*) FROM (SELECT run_id FROM artifacts "
                                f"WHERE run_id IN ({ids}) GROUP BY run_id, kind "
                                "HAVING count(*) > 1) d") == 0


def _running_with_progress(stack: Stack, job_id: int) -> dict[str, Any] | None:
    for brief in stack.get(f"/jobs/{job_id}")["runs"]:
        if brief["status"] == "running":
            run: dict[str, Any] = stack.get(f"/runs/{brief['id']}")
            if run["status"] == "running" and run["sim_time_s"] >= 2 and run["worker"]:
                return run
    return None


def test_kill_9_ten_times(stack: Stack, database: str) -> None:
    stack.start_api()
    stack.start_worker()
    stack.start_worker()
    job = stack.submit(planner="classic", areas=["maze"], runs=8, seconds=25, preset="exact")
    jobs = [job]
    kills: list[int] = []
    attempts_killed: set[tuple[int, int]] = set()
    deadline = time.monotonic() + 300
    while len(kills) < 10:
        assert time.monotonic() < deadline, f"only {len(kills)} kills:\n{stack.tail()}"
        run = None
        for brief in stack.get(f"/jobs/{job['id']}")["runs"]:
            if brief["status"] != "running":
                continue
            candidate = stack.get(f"/runs/{brief['id']}")
            if (candidate["status"] == "running" and candidate["sim_time_s"] >= 2
                    and (candidate["id"], candidate["attempts"]) not in attempts_killed):
                run = candidate
                break
        if run is None:
            if stack.get(f"/jobs/{job['id']}")["status"] == "succeeded":  # need more victims
                job = stack.submit(planner="classic", areas=["maze"], runs=4, seconds=25,
                                   preset="exact")
                jobs.append(job)
            time.sleep(0.3)
            continue
        pid = int(run["worker"].rsplit("-", 1)[1])  # the pool process flying the run
        attempts_killed.add((run["id"], run["attempts"]))
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            continue  # it ended on its own a moment ago
        after = stack.get(f"/runs/{run['id']}")
        if after["status"] == "succeeded" and after["attempts"] == run["attempts"]:
            # The run's result was committed between the poll and the signal: the signal hit
            # the process after it had left this run, so this run was not interrupted.
            continue
        kills.append(run["id"])
    for each in jobs:
        _exactly_one_result_each(stack, stack.wait_job(each["id"], timeout=400))
    killed = [stack.get(f"/runs/{run_id}") for run_id in set(kills)]
    assert all(r["status"] == "succeeded" and r["attempts"] >= 2 for r in killed), killed
    assert all(w.poll() is None for w in stack.workers)  # the worker processes live on


def test_redis_then_postgres_restart_during_a_job(stack: Stack, database: str) -> None:
    stack.start_api()
    stack.start_worker()
    stack.start_worker()
    job = stack.submit(planner="classic", areas=["maze"], runs=4, seconds=60, preset="exact")
    deadline = time.monotonic() + 120
    while _running_with_progress(stack, job["id"]) is None:
        assert time.monotonic() < deadline, stack.tail()
        time.sleep(0.3)
    # Redis keeps nothing on disk here: queued messages are lost, the sweep sends them again.
    stack.servers.redis.shutdown()
    time.sleep(2)
    stack.servers.redis.start()
    time.sleep(3)
    stack.servers.postgres.restart()
    final = stack.wait_job(job["id"], timeout=300)
    _exactly_one_result_each(stack, final)


def test_api_restart_loses_no_job(stack: Stack, database: str) -> None:
    stack.start_api()
    stack.start_worker()
    job = stack.submit(planner="classic", areas=["maze"], runs=3, seconds=40, preset="exact")
    assert stack.api is not None
    stack.kill(stack.api, signal.SIGKILL)
    time.sleep(2)
    stack.start_api()
    final = stack.wait_job(job["id"], timeout=240)
    _exactly_one_result_each(stack, final)
    assert stack.get(f"/jobs/{job['id']}")["status"] == "succeeded"  # and it stays so
