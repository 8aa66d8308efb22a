"""Workers on other hosts: three network namespaces joined by a bridge play three machines.

The server host runs PostgreSQL, Redis, moto's S3-compatible server (the artifact store) and
the API, each on the host's own address; two worker hosts run `flybo worker` each, with data
and cache folders of their own: nothing but the network joins them. A job group flies to the
end and its artifacts download from the API. Then one worker host's link goes down while it
flies a run: the API's sweep requeues the run, the other worker flies it, and the run has one
result and one artifact row per kind; when the link comes back, the cut-off attempt stores
nothing.

Needs root and iproute2; under CI=true it fails rather than skips without them.
"""

from __future__ import annotations

import hashlib
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import httpx
import pytest
from sqlalchemy import Engine, create_engine, func, select

from server.models import Artifact, Job, Run, RunResult
from tests.multihost.netns import Host, hosts, require_netns
from tests.multihost.services import (
    BUCKET,
    api,
    postgres,
    redis_server,
    s3_server,
    seed_area_cache,
    service_env,
    wait_until,
)

pytestmark = pytest.mark.slow

FINAL = {"succeeded", "failed", "cancelled"}
KINDS = ("recording", "mesh", "result")


def _settings(db: str, redis: str, s3: str) -> dict[str, str]:
    """The FLYBO_* settings every host gets: the addresses of the server host's services and
    short liveness times, so that a cut-off worker is noticed within seconds."""
    return {"database_url": db, "broker_url": redis, "artifact_url": f"s3://{BUCKET}/flybo",
            "s3_endpoint_url": s3, "heartbeat_interval_s": "1", "heartbeat_timeout_s": "8",
            "sweep_interval_s": "1", "requeue_queued_after_s": "60"}


def _start_worker(host: Host, folder: Path, settings: dict[str, str], log: Path) -> None:
    seed_area_cache(folder, "maze")
    host.start([sys.executable, "-m", "flybo", "worker", "--concurrency", "1",
                "--threads-per-worker", "1"], service_env(folder, **settings), log)


def _wait_final(base: str, path: str, timeout_s: float = 900.0) -> dict[str, Any]:
    answer: dict[str, Any] = {}

    def final() -> bool:
        nonlocal answer
        answer = httpx.get(f"{base}{path}", timeout=10).json()
        return answer["status"] in FINAL

    wait_until(final, path, timeout_s)
    return answer


def _runs(engine: Engine, **where: Any) -> list[Any]:
    query = select(Run.id, Run.status, Run.worker, Run.attempts).join(Job, Run.job_id == Job.id)
    for column, value in where.items():
        query = query.where(getattr(Job, column) == value)
    with engine.connect() as conn:
        return list(conn.execute(query.order_by(Run.id)))


def _pid(worker: str | None) -> int:
    assert worker is not None
    return int(worker.rsplit("-", 1)[1])


def _stored(engine: Engine, run_id: int) -> tuple[int, list[str]]:
    """The run's result rows and the kinds of its artifact rows."""
    with engine.connect() as conn:
        results = conn.scalar(select(func.count()).where(RunResult.run_id == run_id)) or 0
        kinds = list(conn.scalars(select(Artifact.kind).where(Artifact.run_id == run_id)))
    return results, sorted(kinds)


def test_workers_on_other_hosts_fly_a_group_and_survive_a_cut_link(tmp_path: Path) -> None:
    require_netns()
    logs = tmp_path / "logs"
    logs.mkdir()
    with hosts(3) as (server, first, second), postgres(server, logs) as db:
        settings = _settings(db, redis_server(server, logs), s3_server(server, logs))
        api_env = service_env(tmp_path / "server", **settings)
        token = subprocess.run([sys.executable, "-m", "flybo", "tokens", "create", "--user",
                                "multihost"], env=api_env, capture_output=True, text=True,
                               check=True).stdout.strip()
        base = api(server, api_env, logs)
        for i, host in enumerate((first, second), start=1):
            _start_worker(host, tmp_path / f"worker{i}", settings, logs / f"worker{i}.log")
        engine = create_engine(db)
        auth = {"Authorization": f"Bearer {token}"}
        try:
            _group_flies_and_downloads(base, auth, engine, (first, second))
            _cut_link_mid_run(base, auth, engine, first, second)
        finally:
            engine.dispose()
    # Nothing of the runs went through a folder: the API's own holds no artifacts.
    assert not (tmp_path / "server" / "data" / "artifacts").exists()


def _group_flies_and_downloads(base: str, auth: dict[str, str], engine: Engine,
                               workers: tuple[Host, Host]) -> None:
    group = httpx.post(f"{base}/api/v1/groups", headers=auth, timeout=60, json={
        "planners": ["classic"], "areas": ["maze"], "runs": 3, "seconds": 25})
    assert group.status_code == 201, group.text
    done = _wait_final(base, f"/api/v1/groups/{group.json()['id']}")
    assert done["status"] == "succeeded", done
    with engine.connect() as conn:
        job_ids = list(conn.scalars(select(Job.id).where(Job.group_id == group.json()["id"])))
    runs = [r for job_id in job_ids for r in _runs(engine, id=job_id)]
    assert len(runs) == 3 and {r.status for r in runs} == {"succeeded"}
    pids = set().union(*(w.pids() for w in workers))
    assert {_pid(r.worker) for r in runs} <= pids  # flown on the worker hosts
    for run in runs:
        with engine.connect() as conn:
            rows = {a.kind: a for a in conn.execute(
                select(Artifact.kind, Artifact.sha256).where(Artifact.run_id == run.id))}
        assert set(KINDS) <= set(rows)
        for kind in KINDS:
            got = httpx.get(f"{base}/api/v1/runs/{run.id}/artifacts/{kind}", timeout=60)
            assert got.status_code == 200, got.text
            assert hashlib.sha256(got.content).hexdigest() == rows[kind].sha256


def _cut_link_mid_run(base: str, auth: dict[str, str], engine: Engine, cut: Host,
                      other: Host) -> None:
    job = httpx.post(f"{base}/api/v1/jobs", headers=auth, timeout=60, json={
        "planner": "classic", "areas": ["maze"], "runs": 2, "seconds": 240})
    assert job.status_code == 201, job.text
    job_id = job.json()["id"]
    victim: list[int] = []

    def flying_on_cut_host() -> bool:
        pids = cut.pids()
        victim[:] = [r.id for r in _runs(engine, id=job_id)
                     if r.status == "running" and r.worker and _pid(r.worker) in pids]
        return bool(victim)

    wait_until(flying_on_cut_host, "a run on the first worker host", timeout_s=300)
    run_id = victim[0]
    cut.set_link(False)
    cut_at = time.monotonic()
    try:
        done = _wait_final(base, f"/api/v1/jobs/{job_id}")
        assert done["status"] == "succeeded", done
        assert time.monotonic() - cut_at > 8  # it waited for the heartbeat to go stale
        (run,) = [r for r in _runs(engine, id=job_id) if r.id == run_id]
        assert run.attempts == 2
        assert _pid(run.worker) in other.pids()  # finished on the other worker host
        assert _stored(engine, run_id) == (1, sorted([*KINDS, "log"]))
    finally:
        cut.set_link(True)
    # The cut-off attempt reconnects and finds its claim gone: it stores nothing more.
    time.sleep(15)
    assert _stored(engine, run_id) == (1, sorted([*KINDS, "log"]))
    got = httpx.get(f"{base}/api/v1/runs/{run_id}/artifacts/recording", timeout=60)
    assert got.status_code == 200
