"""Polling `GET /api/v1/jobs/{id}` on real SQLite and PostgreSQL: the Core-query answer equals
the ORM one, its strong ETag, 304 on If-None-Match, the polling headers and 404s."""

from __future__ import annotations

from typing import Any

from fastapi.testclient import TestClient
from sqlalchemy import select, update
from sqlalchemy.orm import Session, selectinload, sessionmaker

from server.jobs import job_out
from server.models import AreaRow, Job, PlannerRow, Run, User
from tests.server.conftest import Tokens

JOB = {"planner": "classic", "areas": ["maze"], "runs": 3, "seconds": 30, "preset": "default"}


def _submit(client: TestClient, tokens: Tokens, **changes: Any) -> dict[str, Any]:
    response = client.post("/api/v1/jobs", json={**JOB, **changes}, headers=tokens.auth("alice"))
    assert response.status_code == 201, response.text
    job: dict[str, Any] = response.json()
    return job


def _orm_body(sessions: sessionmaker[Session], job_id: int) -> bytes:
    """The body the ORM path answered with: `job_out` of the fully loaded job."""
    with sessions() as session:
        job = session.scalar(select(Job).where(Job.id == job_id).options(
            selectinload(Job.runs).selectinload(Run.area), selectinload(Job.planner),
            selectinload(Job.user)))
        assert job is not None
        return job_out(job).model_dump_json().encode()


def _set_run(sessions: sessionmaker[Session], run_id: int, **values: Any) -> None:
    with sessions() as session:
        session.execute(update(Run).where(Run.id == run_id).values(**values))
        session.commit()


def test_etag_is_present_and_stable_while_nothing_changes(client: TestClient,
                                                          tokens: Tokens) -> None:
    job = _submit(client, tokens)
    first = client.get(f"/api/v1/jobs/{job['id']}")
    second = client.get(f"/api/v1/jobs/{job['id']}")
    assert first.status_code == second.status_code == 200
    etag = first.headers["etag"]
    assert etag.startswith('"') and etag.endswith('"') and len(etag) > 10
    assert second.headers["etag"] == etag
    assert first.content == second.content
    assert first.headers["cache-control"] == "no-cache"
    assert first.headers["retry-after"] == "2"  # queued: poll again
    assert first.headers["content-type"] == "application/json"


def test_if_none_match_gives_304_without_a_body(client: TestClient, tokens: Tokens) -> None:
    job = _submit(client, tokens)
    etag = client.get(f"/api/v1/jobs/{job['id']}").headers["etag"]
    for sent in (etag, f'"other", {etag}', f"W/{etag}", "*"):
        unchanged = client.get(f"/api/v1/jobs/{job['id']}", headers={"If-None-Match": sent})
        assert unchanged.status_code == 304, sent
        assert unchanged.content == b""
        assert unchanged.headers["etag"] == etag
        assert unchanged.headers["cache-control"] == "no-cache"
    stale = client.get(f"/api/v1/jobs/{job['id']}", headers={"If-None-Match": '"stale"'})
    assert stale.status_code == 200 and stale.json()["id"] == job["id"]


def test_a_changed_run_changes_the_etag_and_the_body(client: TestClient, tokens: Tokens,
                                                     sessions: sessionmaker[Session]) -> None:
    job = _submit(client, tokens)
    url = f"/api/v1/jobs/{job['id']}"
    before = client.get(url)
    etag = before.headers["etag"]
    assert before.json()["status"] == "queued" and before.json()["progress"] == 0

    first, second, third = (r["id"] for r in job["runs"])
    _set_run(sessions, first, status="running", progress=0.25)
    running = client.get(url, headers={"If-None-Match": etag})
    assert running.status_code == 200
    assert running.headers["etag"] != etag
    body = running.json()
    assert body["status"] == "running" and body["progress"] == round(0.25 / 3, 4)
    assert [(r["id"], r["status"], r["progress"]) for r in body["runs"]] == [
        (first, "running", 0.25), (second, "queued", 0.0), (third, "queued", 0.0)]
    assert running.headers["retry-after"] == "2"

    # Progress alone (the worker's heartbeat) is a change too.
    _set_run(sessions, first, progress=0.5)
    advanced = client.get(url, headers={"If-None-Match": running.headers["etag"]})
    assert advanced.status_code == 200 and advanced.json()["runs"][0]["progress"] == 0.5

    for run_id in (first, second, third):
        _set_run(sessions, run_id, status="succeeded", progress=0.9)
    done = client.get(url, headers={"If-None-Match": advanced.headers["etag"]})
    assert done.status_code == 200
    assert done.json()["status"] == "succeeded" and done.json()["progress"] == 1
    assert "retry-after" not in done.headers  # final: nothing more to wait for
    again = client.get(url, headers={"If-None-Match": done.headers["etag"]})
    assert again.status_code == 304 and "retry-after" not in again.headers


def test_unknown_or_wrong_ids(client: TestClient, tokens: Tokens) -> None:
    _submit(client, tokens)
    for job_id in (999_999, 2**31 - 1):
        missing = client.get(f"/api/v1/jobs/{job_id}")
        assert missing.status_code == 404
        assert missing.json() == {"detail": f"no job with id {job_id}"}
        assert "etag" not in missing.headers
    for wrong in ("0", "-3", "abc", str(2**31)):
        refused = client.get(f"/api/v1/jobs/{wrong}")
        assert refused.status_code == 422, wrong
        assert refused.json()["detail"]


def test_the_body_is_the_orm_paths(client: TestClient, tokens: Tokens,
                                   sessions: sessionmaker[Session]) -> None:
    job = _submit(client, tokens)
    url = f"/api/v1/jobs/{job['id']}"
    assert client.get(url).content == _orm_body(sessions, job["id"])

    # Mixed states, a final run whose stored progress is below 1, and a second area that
    # comes first in run order only from the second run on.
    first, second, third = (r["id"] for r in job["runs"])
    with sessions() as session:
        other = AreaRow(name="cave-test", builtin=False, content_hash="0" * 64, plateau_s=100.0,
                        voxel_size=0.2, stats={})
        session.add(other)
        session.commit()
        other_id = other.id
    _set_run(sessions, first, status="failed", progress=0.3)
    _set_run(sessions, second, status="running", progress=0.123456, area_id=other_id)
    _set_run(sessions, third, status="cancelled")
    body = client.get(url)
    assert body.content == _orm_body(sessions, job["id"])
    answer = body.json()
    assert answer["areas"] == ["maze", "cave-test"]
    assert answer["status"] == "running"
    assert answer["progress"] == round((1.0 + 0.123456 + 1.0) / 3, 4)
    assert [r["progress"] for r in answer["runs"]] == [1.0, 0.1235, 1.0]

    # A re-run in a job group.
    grouped = client.post("/api/v1/groups", headers=tokens.auth("alice"), json={
        "planners": ["classic"], "areas": ["maze"], "runs": 1, "seconds": 30})
    assert grouped.status_code == 201, grouped.text
    grouped_id = grouped.json()["planners"][0]["jobs"][0]
    rerun = client.post(f"/api/v1/jobs/{grouped_id}/rerun", headers=tokens.auth("alice"))
    assert rerun.status_code == 201, rerun.text
    rerun_body = client.get(f"/api/v1/jobs/{rerun.json()['id']}")
    assert rerun_body.json()["rerun_of"] == grouped_id
    assert rerun_body.json()["group_id"] == grouped.json()["id"]
    assert rerun_body.content == _orm_body(sessions, rerun.json()["id"])


def test_a_job_without_runs(client: TestClient, tokens: Tokens,
                            sessions: sessionmaker[Session]) -> None:
    # Not made through the API (every job has runs), but the answer must not lose the job.
    with sessions() as session:
        alice = session.scalar(select(User).where(User.name == "alice"))
        planner = session.scalars(select(PlannerRow).where(PlannerRow.name == "classic")).first()
        assert alice is not None and planner is not None
        empty = Job(user_id=alice.id, planner_id=planner.id, preset="default", seconds=None,
                    runs_per_area=1, request_hash="0" * 64)
        session.add(empty)
        session.commit()
        empty_id = empty.id
    answer = client.get(f"/api/v1/jobs/{empty_id}")
    assert answer.status_code == 200
    assert answer.content == _orm_body(sessions, empty_id)
    body = answer.json()
    assert (body["status"], body["progress"], body["runs"], body["areas"]) == (
        "succeeded", 1, [], [])
    assert "retry-after" not in answer.headers
