"""Job groups on real SQLite and PostgreSQL and the real filesystem broker: creation (one job per
planner), idempotency, refusals that store nothing, auth, progress and cancellation."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import httpx
import pytest
from fastapi.testclient import TestClient
from sqlalchemy import func, select, update
from sqlalchemy.orm import Session, sessionmaker

from server.app import create_app
from server.models import Job, JobGroup, Run, RunState
from server.settings import Settings

GROUP = {"planners": ["classic", "rapid"], "areas": ["maze"], "runs": 2, "seconds": 30,
         "preset": "default"}


def _counts(sessions: sessionmaker[Session]) -> tuple[int, int, int]:
    with sessions() as s:
        return (s.scalar(select(func.count(JobGroup.id))) or 0,
                s.scalar(select(func.count(Job.id))) or 0,
                s.scalar(select(func.count(Run.id))) or 0)


def _submit(client: TestClient, headers: dict[str, str], **changes: Any) -> Any:
    return client.post("/api/v1/groups", json={**GROUP, **changes}, headers=headers)


def test_a_group_holds_one_job_per_planner(client: TestClient, tokens: Any,
                                           sessions: sessionmaker[Session],
                                           settings: Settings) -> None:
    response = _submit(client, tokens.auth("alice"), name="suite one")
    assert response.status_code == 201, response.text
    group = response.json()
    assert group["name"] == "suite one" and group["owner"] == "alice"
    assert group["status"] == "queued" and group["runs"] == 4 and group["done"] == 0
    assert group["by_status"]["queued"] == 4 and group["areas"] == ["maze"]
    assert [p["planner"] for p in group["planners"]] == ["classic-v3", "rapid-v2"]
    assert all(p["runs"] == 2 and len(p["jobs"]) == 1 and p["simulated_s"] == 60
               for p in group["planners"])
    assert _counts(sessions) == (1, 2, 4)
    for planner in group["planners"]:
        job = client.get(f"/api/v1/jobs/{planner['jobs'][0]}").json()
        assert [(r["area"], r["seed"]) for r in job["runs"]] == [("maze", 0), ("maze", 1)]
        assert job["seconds"] == 30 and job["planner"] == planner["planner"]
    # Every run is on the broker, sent after the commit.
    assert len(list((settings.broker_folder / "queue").iterdir())) == 4
    listed = client.get("/api/v1/groups").json()
    assert listed["total"] == 1 and listed["items"][0]["id"] == group["id"]
    assert client.get("/api/v1/groups", params={"owner": "bob"}).json()["total"] == 0


def test_all_and_time_scale(client: TestClient, tokens: Any,
                            sessions: sessionmaker[Session]) -> None:
    response = _submit(client, tokens.auth("admin"), planners=["all"], runs=1, seconds=None,
                       time_scale=0.01)
    assert response.status_code == 201, response.text
    group = response.json()
    planners = [p["planner"] for p in group["planners"]]
    # "all" is the default version of every registered name, one each: its newest original
    # version (fuel-v2 is a variant of fuel-v1).
    assert "classic-v3" in planners and "classic-v2" not in planners
    assert "fuel-v1" in planners and "fuel-v2" not in planners
    names = [p.rsplit("-v", 1)[0] for p in planners]
    assert len(names) == len(set(names)) >= 2
    # MAZE's plateau is 700 s: one run of 7 s per planner.
    assert all(p["simulated_s"] == pytest.approx(7.0) for p in group["planners"])
    assert group["time_scale"] == 0.01 and group["seconds"] is None


def test_idempotency_key(client: TestClient, tokens: Any,
                         sessions: sessionmaker[Session]) -> None:
    headers = {**tokens.auth("alice"), "Idempotency-Key": "suite-1"}
    first = _submit(client, headers)
    second = _submit(client, headers)
    assert first.status_code == second.status_code == 201
    assert first.json()["id"] == second.json()["id"]
    assert second.headers["Idempotent-Replayed"] == "true"
    assert _counts(sessions) == (1, 2, 4)
    clash = _submit(client, headers, runs=1)
    assert clash.status_code == 409 and "Idempotency-Key" in clash.json()["detail"]
    bob = _submit(client, {**tokens.auth("bob"), "Idempotency-Key": "suite-1"})
    assert bob.status_code == 201 and bob.json()["id"] != first.json()["id"]


@pytest.mark.parametrize(("changes", "needle"), [
    ({"planners": ["classic", "teleport"]}, "classic-v1"),  # lists the known planners
    ({"areas": ["maze", "atlantis"]}, "maze"),  # lists the known areas
    ({"planners": ["classic", "classic-v3"]}, "repeat"),
    ({"planners": []}, "planners"),
    ({"areas": ["maze", "maze"]}, "repeat"),
    ({"areas": ["all", "maze"]}, "alone"),
    ({"runs": 0}, "runs"),
    ({"preset": "turbo"}, "default"),
    ({"seconds": 10, "time_scale": 0.5}, "time_scale"),
    ({"time_scale": 2}, "time_scale"),
    ({"seconds": 1e9}, "seconds"),
    ({"colour": "red"}, "colour"),
])
def test_bad_groups_are_refused_and_nothing_is_stored(
    client: TestClient, tokens: Any, sessions: sessionmaker[Session], changes: dict[str, Any],
    needle: str,
) -> None:
    response = _submit(client, tokens.auth("alice"), **changes)
    assert response.status_code == 422, response.text
    assert needle in response.json()["detail"]
    assert _counts(sessions) == (0, 0, 0)


def test_auth_is_needed(client: TestClient, tokens: Any,
                        sessions: sessionmaker[Session]) -> None:
    missing = client.post("/api/v1/groups", json=GROUP)
    assert missing.status_code == 401 and "token" in missing.json()["detail"]
    wrong = client.post("/api/v1/groups", json=GROUP, headers={"Authorization": "Bearer nope"})
    assert wrong.status_code == 401
    assert _counts(sessions) == (0, 0, 0)
    group = _submit(client, tokens.auth("alice")).json()
    assert client.post(f"/api/v1/groups/{group['id']}/cancel").status_code == 401


def test_quotas_apply_to_the_whole_group(settings: Settings, sessions: sessionmaker[Session],
                                         tokens: Any) -> None:
    app = create_app(settings.model_copy(update={"quota_concurrent_runs": 3}), sweeper=False,
                     sync_areas=False)
    with TestClient(app) as client:
        refused = _submit(client, tokens.auth("alice"))  # 4 runs
        assert refused.status_code == 429 and "at most 3" in refused.json()["detail"]
        assert _counts(sessions) == (0, 0, 0)
        assert _submit(client, tokens.auth("alice"), runs=1).status_code == 201
    app = create_app(settings.model_copy(update={"quota_jobs_per_day": 1}), sweeper=False,
                     sync_areas=False)
    with TestClient(app) as client:
        # Two planners make two jobs: over a quota of one job a day, refused whole.
        refused = _submit(client, tokens.auth("bob"))
        assert refused.status_code == 429 and "jobs per day" in refused.json()["detail"]
        assert _counts(sessions) == (1, 2, 2)


def test_progress_and_cancel(client: TestClient, tokens: Any,
                             sessions: sessionmaker[Session]) -> None:
    group = _submit(client, tokens.auth("alice")).json()
    classic_job = group["planners"][0]["jobs"][0]
    with sessions() as s:
        first, second = s.scalars(select(Run.id).where(Run.job_id == classic_job)
                                  .order_by(Run.id)).all()
        s.execute(update(Run).where(Run.id == first).values(status=RunState.SUCCEEDED.value,
                                                            progress=1.0))
        s.execute(update(Run).where(Run.id == second).values(status=RunState.RUNNING.value,
                                                             progress=0.5))
        s.commit()
    shown = client.get(f"/api/v1/groups/{group['id']}").json()
    assert shown["status"] == "running" and shown["done"] == 1
    assert shown["by_status"] == {"queued": 2, "running": 1, "succeeded": 1, "failed": 0,
                                  "cancelled": 0}
    classic, rapid = shown["planners"]
    assert classic["progress"] == 0.75 and classic["done"] == 1 and rapid["progress"] == 0
    assert shown["progress"] == pytest.approx(0.375)
    assert client.get("/api/v1/groups/999999").status_code == 404

    forbidden = client.post(f"/api/v1/groups/{group['id']}/cancel", headers=tokens.auth("bob"))
    assert forbidden.status_code == 403 and "owner" in forbidden.json()["detail"]
    cancelled = client.post(f"/api/v1/groups/{group['id']}/cancel",
                            headers=tokens.auth("alice")).json()
    # Queued runs end now; the running one is asked to stop and ends when its worker sees it.
    assert cancelled["by_status"] == {"queued": 0, "running": 1, "succeeded": 1, "failed": 0,
                                      "cancelled": 2}
    with sessions() as s:
        assert s.scalar(select(Run.cancel_requested).where(Run.id == second)) is True


def _finish(sessions: sessionmaker[Session], job_id: int, *states: RunState) -> None:
    """End the job's runs, in id order, in `states`."""
    with sessions() as s:
        ids = s.scalars(select(Run.id).where(Run.job_id == job_id).order_by(Run.id)).all()
        for run_id, state in zip(ids, states, strict=True):
            s.execute(update(Run).where(Run.id == run_id).values(status=state.value,
                                                                 progress=1.0))
        s.commit()


def test_a_rerun_joins_the_group_in_place_of_the_job(client: TestClient, tokens: Any,
                                                     sessions: sessionmaker[Session],
                                                     settings: Settings) -> None:
    group = _submit(client, tokens.auth("alice")).json()
    classic_job, rapid_job = (p["jobs"][0] for p in group["planners"])
    _finish(sessions, classic_job, RunState.FAILED, RunState.SUCCEEDED)
    _finish(sessions, rapid_job, RunState.SUCCEEDED, RunState.SUCCEEDED)
    before = client.get(f"/api/v1/groups/{group['id']}").json()
    assert before["status"] == "failed" and before["done"] == 4 and before["progress"] == 1

    response = client.post(f"/api/v1/jobs/{classic_job}/rerun", headers=tokens.auth("alice"))
    assert response.status_code == 201, response.text
    rerun = response.json()
    assert rerun["group_id"] == group["id"] and rerun["rerun_of"] == classic_job
    assert len(list((settings.broker_folder / "queue").iterdir())) == 4 + 2
    # The old job keeps its group and its runs; the group counts the re-run instead of it.
    old = client.get(f"/api/v1/jobs/{classic_job}").json()
    assert old["group_id"] == group["id"] and old["status"] == "failed"
    shown = client.get(f"/api/v1/groups/{group['id']}").json()
    assert [(p["planner"], p["jobs"]) for p in shown["planners"]] == [
        ("classic-v3", [rerun["id"]]), ("rapid-v2", [rapid_job])]
    assert shown["runs"] == 4 and shown["done"] == 2 and shown["status"] == "running"
    assert shown["by_status"] == {"queued": 2, "running": 0, "succeeded": 2, "failed": 0,
                                  "cancelled": 0}
    assert shown["progress"] == 0.5 and shown["planners"][0]["simulated_s"] == 60
    assert client.get("/api/v1/groups").json()["items"][0]["runs"] == 4

    _finish(sessions, rerun["id"], RunState.SUCCEEDED, RunState.SUCCEEDED)
    after = client.get(f"/api/v1/groups/{group['id']}").json()
    assert after["status"] == "succeeded" and after["done"] == 4 and after["progress"] == 1
    assert after["by_status"]["succeeded"] == 4 and after["by_status"]["failed"] == 0

    # A re-run of the re-run, and a second re-run of the first job: still one job of the line
    # counted, the newest.
    again = client.post(f"/api/v1/jobs/{rerun['id']}/rerun", headers=tokens.auth("alice"))
    third = client.post(f"/api/v1/jobs/{classic_job}/rerun", headers=tokens.auth("alice"))
    assert again.json()["group_id"] == third.json()["group_id"] == group["id"]
    shown = client.get(f"/api/v1/groups/{group['id']}").json()
    assert [p["jobs"] for p in shown["planners"]] == [[third.json()["id"]], [rapid_job]]
    assert shown["runs"] == 4 and shown["by_status"]["queued"] == 2
    # Cancelling the group reaches every job in it, replaced ones included.
    cancelled = client.post(f"/api/v1/groups/{group['id']}/cancel",
                            headers=tokens.auth("alice")).json()
    assert cancelled["by_status"]["cancelled"] == 2
    assert client.get(f"/api/v1/jobs/{again.json()['id']}").json()["status"] == "cancelled"


def test_flybo_benchmark_against_a_real_service(tmp_path: Path) -> None:
    """`flybo benchmark` end to end: `flybo serve` with one real worker, one planner x one
    area x one run of a few simulated seconds; then Ctrl-C while waiting leaves a group
    running and says how to follow it."""
    from tests.server.test_end_to_end import _env as service_env
    from tests.server.test_end_to_end import (
        _free_port,
        _processes,
        _tail,
        _token,
        _wait_healthy,
    )

    port = _free_port()
    base = f"http://127.0.0.1:{port}"
    env = service_env(tmp_path)
    logs = tmp_path / "logs"
    logs.mkdir()
    token = _token(env, "gina")
    flybo = [sys.executable, "-m", "flybo", "benchmark", "--server", base, "--token", token]
    with _processes([["serve", "--port", str(port), "--workers", "1", "--no-viewer"]], env,
                    logs):
        _wait_healthy(base, logs)
        done = subprocess.run([*flybo, "--planners", "classic", "--areas", "maze", "--runs",
                               "1", "--seconds", "3", "--name", "tiny"], env=env,
                              capture_output=True, text=True, timeout=240)
        assert done.returncode == 0, done.stdout + done.stderr + _tail(logs)
        assert "tiny): succeeded" in done.stdout and "classic-v3" in done.stdout
        group = httpx.get(f"{base}/api/v1/groups/1").json()
        assert group["by_status"]["succeeded"] == 1 and group["status"] == "succeeded"

        refused = subprocess.run([*flybo, "--planners", "teleport", "--areas", "maze"],
                                 env=env, capture_output=True, text=True, timeout=60)
        assert refused.returncode == 2 and "classic-v1" in refused.stderr

        # Ctrl-C as from a user's terminal. A test run started in the background ignores
        # SIGINT, and a child inherits an ignored signal across exec; a handler of ours is
        # reset to the default there instead.
        previous = signal.signal(signal.SIGINT, signal.default_int_handler)
        try:
            waiting = subprocess.Popen([*flybo, "--planners", "classic", "--areas", "maze",
                                        "--runs", "1", "--seconds", "600"], env=env,
                                       stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                       text=True)
        finally:
            signal.signal(signal.SIGINT, previous)
        deadline = time.monotonic() + 60
        while httpx.get(f"{base}/api/v1/groups").json()["total"] < 2:
            assert time.monotonic() < deadline and waiting.poll() is None, _tail(logs)
            time.sleep(0.3)
        time.sleep(1.0)  # into the waiting loop
        waiting.send_signal(signal.SIGINT)
        _, err = waiting.communicate(timeout=30)
        assert waiting.returncode == 130 and "flybo benchmark --follow 2" in err
        assert httpx.get(f"{base}/api/v1/groups/2").json()["status"] in ("queued", "running")
        cancelled = httpx.post(f"{base}/api/v1/groups/2/cancel",
                               headers={"Authorization": f"Bearer {token}"})
        assert cancelled.status_code == 200
