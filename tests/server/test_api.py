"""The REST API on real SQLite and PostgreSQL: reads, jobs, auth, quotas, idempotency, errors."""

from __future__ import annotations

import json
from typing import Any

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import func, select, update
from sqlalchemy.orm import Session, sessionmaker

from server.models import Job, Run
from server.settings import Settings
from tests.web.stored import current_version

JOB = {"planner": "classic", "areas": ["maze"], "runs": 2, "seconds": 30, "preset": "default"}


def _counts(sessions: sessionmaker[Session]) -> tuple[int, int]:
    with sessions() as s:
        return (s.scalar(select(func.count(Job.id))) or 0, s.scalar(select(func.count(Run.id)))
                or 0)


def _submit(client: TestClient, token_headers: dict[str, str], **changes: Any) -> Any:
    return client.post("/api/v1/jobs", json={**JOB, **changes}, headers=token_headers)


def test_health_and_docs(client: TestClient) -> None:
    assert client.get("/healthz").json() == {"status": "ok"}
    assert client.get("/docs").status_code == 200
    paths = client.get("/openapi.json").json()["paths"]
    assert {"/api/v1/jobs", "/api/v1/leaderboard", "/api/v1/runs/{run_id}/series"} <= set(paths)


def test_areas_and_planners(client: TestClient) -> None:
    maze = client.get("/api/v1/areas/maze").json()
    assert maze["builtin"] and maze["plateau_s"] == 700 and maze["stats"]["faces"] > 0
    assert [a["name"] for a in client.get("/api/v1/areas").json()] == ["maze"]
    missing = client.get("/api/v1/areas/atlantis")
    assert missing.status_code == 404 and "atlantis" in missing.json()["detail"]
    planners = client.get("/api/v1/planners").json()
    assert "classic-v1" in [p["id"] for p in planners]
    classic = client.get("/api/v1/planners/classic").json()
    assert classic["builtin"] and "defaults" in classic["config"]
    # What each built-in version is to its paper; a bare name is its newest original version.
    methods = {p["id"]: p["method"] for p in planners}
    assert (methods["nbvp-v1"], methods["nbvp-v2"]) == ("variant", "original")
    assert client.get("/api/v1/planners/fuel").json()["id"] == "fuel-v1"
    unknown = client.get("/api/v1/planners/teleport")
    assert unknown.status_code == 404 and "classic-v1" in unknown.json()["detail"]


def test_planner_names_are_read_as_the_command_line_reads_them(client: TestClient,
                                                                tokens: Any) -> None:
    newest = client.get("/api/v1/planners/classic").json()["id"]
    for name in ("Classic", " CLASSIC "):
        assert client.get(f"/api/v1/planners/{name}").json()["id"] == newest, name
    assert client.get("/api/v1/planners/Classic-V1").json()["id"] == "classic-v1"
    job = _submit(client, tokens.auth("alice"), planner="Classic", runs=1)
    assert job.status_code == 201 and job.json()["planner"] == newest, job.text
    assert client.get("/api/v1/planners/classic-v9").status_code == 404


def test_create_and_read_a_job(client: TestClient, tokens: Any) -> None:
    response = _submit(client, tokens.auth("alice"))
    assert response.status_code == 201, response.text
    job = response.json()
    assert job["status"] == "queued" and job["progress"] == 0
    assert [(r["area"], r["seed"], r["status"]) for r in job["runs"]] == [
        ("maze", 0, "queued"), ("maze", 1, "queued")]
    again = client.get(f"/api/v1/jobs/{job['id']}").json()
    assert again["id"] == job["id"] and again["owner"] == "alice"
    run = client.get(f"/api/v1/runs/{job['runs'][0]['id']}").json()
    assert run["status"] == "queued" and run["seconds"] == 30 and run["result"] is None
    plateau = _submit(client, tokens.auth("alice"), seconds=None, runs=1).json()
    assert client.get(f"/api/v1/runs/{plateau['runs'][0]['id']}").json()["seconds"] == 700


def test_the_job_is_on_the_real_broker(client: TestClient, tokens: Any,
                                       settings: Settings) -> None:
    _submit(client, tokens.auth("alice"))
    messages = list((settings.broker_folder / "queue").iterdir())
    assert len(messages) == 2  # one message per run, in kombu's filesystem transport


def test_each_message_carries_a_soft_limit_before_the_hard_one(
    client: TestClient, tokens: Any, settings: Settings,
) -> None:
    _submit(client, tokens.auth("alice"), runs=1, seconds=100)
    (message,) = (settings.broker_folder / "queue").iterdir()
    hard, soft = json.loads(message.read_text())["headers"]["timelimit"]
    assert hard == settings.run_time_limit_s(100) == 400
    assert soft == settings.run_soft_time_limit_s(100) == 340  # a minute to fail cleanly
    short = settings.model_copy(update={"run_time_limit_base_s": 20.0})
    assert short.run_soft_time_limit_s(0) == 15  # a quarter of a short limit


def test_listing_is_paginated_and_filtered(client: TestClient, tokens: Any) -> None:
    for _ in range(3):
        _submit(client, tokens.auth("alice"), runs=1)
    _submit(client, tokens.auth("bob"), runs=1)
    page = client.get("/api/v1/jobs", params={"limit": 2, "offset": 1}).json()
    assert page["total"] == 4 and page["limit"] == 2 and len(page["items"]) == 2
    assert [j["owner"] for j in client.get("/api/v1/jobs", params={"owner": "bob"}).json()[
        "items"]] == ["bob"]
    assert client.get("/api/v1/jobs", params={"area": "warehouse-x"}).json()["total"] == 0
    assert client.get("/api/v1/jobs", params={"limit": 0}).status_code == 422


def test_auth_is_needed_to_create(client: TestClient, tokens: Any,
                                  sessions: sessionmaker[Session]) -> None:
    missing = client.post("/api/v1/jobs", json=JOB)
    assert missing.status_code == 401 and "token" in missing.json()["detail"]
    wrong = client.post("/api/v1/jobs", json=JOB, headers={"Authorization": "Bearer nope"})
    assert wrong.status_code == 401 and "invalid" in wrong.json()["detail"]
    assert _counts(sessions) == (0, 0)


@pytest.mark.parametrize(("changes", "needle"), [
    ({"planner": "teleport"}, "classic-v1"),
    ({"areas": ["atlantis"]}, "atlantis"),
    ({"areas": []}, "areas"),
    ({"areas": ["maze", "maze"]}, "repeat"),
    ({"runs": 0}, "runs"),
    ({"runs": 1000}, "runs"),
    ({"seconds": -5}, "seconds"),
    ({"seconds": 1e9}, "seconds"),
    ({"preset": "turbo"}, "default"),
    ({"colour": "red"}, "colour"),
])
def test_bad_jobs_are_refused_and_nothing_is_stored(
    client: TestClient, tokens: Any, sessions: sessionmaker[Session], changes: dict[str, Any],
    needle: str,
) -> None:
    before = _counts(sessions)
    response = _submit(client, tokens.auth("alice"), **changes)
    assert response.status_code == 422, response.text
    assert needle in response.json()["detail"]
    assert _counts(sessions) == before


def test_malformed_json_is_a_422(client: TestClient, tokens: Any) -> None:
    response = client.post("/api/v1/jobs", content=b"{not json",
                           headers={**tokens.auth("alice"), "Content-Type": "application/json"})
    assert response.status_code == 422 and response.json()["detail"]


def test_idempotency_key(client: TestClient, tokens: Any,
                         sessions: sessionmaker[Session]) -> None:
    headers = {**tokens.auth("alice"), "Idempotency-Key": "abc-123"}
    first = client.post("/api/v1/jobs", json=JOB, headers=headers)
    second = client.post("/api/v1/jobs", json=JOB, headers=headers)
    assert first.status_code == second.status_code == 201
    assert first.json()["id"] == second.json()["id"]
    assert second.headers["Idempotent-Replayed"] == "true"
    assert _counts(sessions) == (1, 2)
    clash = client.post("/api/v1/jobs", json={**JOB, "runs": 1}, headers=headers)
    assert clash.status_code == 409 and "Idempotency-Key" in clash.json()["detail"]
    # Keys are per user: bob's identical key is his own job.
    bob = client.post("/api/v1/jobs", json=JOB,
                      headers={**tokens.auth("bob"), "Idempotency-Key": "abc-123"})
    assert bob.status_code == 201 and bob.json()["id"] != first.json()["id"]


def test_cancel_is_for_the_owner_or_an_admin(client: TestClient, tokens: Any) -> None:
    job = _submit(client, tokens.auth("alice")).json()
    forbidden = client.post(f"/api/v1/jobs/{job['id']}/cancel", headers=tokens.auth("bob"))
    assert forbidden.status_code == 403 and "owner" in forbidden.json()["detail"]
    assert client.post(f"/api/v1/jobs/{job['id']}/cancel").status_code == 401
    cancelled = client.post(f"/api/v1/jobs/{job['id']}/cancel", headers=tokens.auth("alice"))
    assert cancelled.status_code == 200
    assert cancelled.json()["status"] == "cancelled"
    assert {r["status"] for r in cancelled.json()["runs"]} == {"cancelled"}
    other = _submit(client, tokens.auth("bob")).json()
    by_admin = client.post(f"/api/v1/jobs/{other['id']}/cancel", headers=tokens.auth("admin"))
    assert by_admin.json()["status"] == "cancelled"
    assert client.post("/api/v1/jobs/999999/cancel",
                       headers=tokens.auth("admin")).status_code == 404


def test_rerun_makes_a_new_job_and_keeps_the_old(client: TestClient, tokens: Any) -> None:
    job = _submit(client, tokens.auth("alice")).json()
    client.post(f"/api/v1/jobs/{job['id']}/cancel", headers=tokens.auth("alice"))
    assert client.post(f"/api/v1/jobs/{job['id']}/rerun",
                       headers=tokens.auth("bob")).status_code == 403
    again = client.post(f"/api/v1/jobs/{job['id']}/rerun", headers=tokens.auth("alice"))
    assert again.status_code == 201
    new = again.json()
    assert new["id"] != job["id"] and new["rerun_of"] == job["id"]
    assert new["group_id"] is None  # a re-run of a job outside any group stays outside
    assert new["status"] == "queued" and len(new["runs"]) == 2 and new["seconds"] == 30
    assert client.get(f"/api/v1/jobs/{job['id']}").json()["status"] == "cancelled"


def test_a_job_shows_its_group(client: TestClient, tokens: Any) -> None:
    plain = _submit(client, tokens.auth("alice"))
    assert plain.status_code == 201 and plain.json()["group_id"] is None
    group = client.post("/api/v1/groups", headers=tokens.auth("alice"), json={
        "planners": ["classic"], "areas": ["maze"], "runs": 1, "seconds": 30}).json()
    grouped_id = group["planners"][0]["jobs"][0]
    grouped = client.get(f"/api/v1/jobs/{grouped_id}").json()
    assert grouped["group_id"] == group["id"] and grouped["planner"] == "classic-v3"
    assert client.get(f"/api/v1/jobs/{plain.json()['id']}").json()["group_id"] is None
    listed = client.get("/api/v1/jobs").json()["items"]
    assert {j["id"]: j["group_id"] for j in listed} == {grouped_id: group["id"],
                                                        plain.json()["id"]: None}


def test_run_log_is_private(client: TestClient, tokens: Any) -> None:
    job = _submit(client, tokens.auth("alice")).json()
    run_id = job["runs"][0]["id"]
    assert client.get(f"/api/v1/runs/{run_id}/log").status_code == 401
    assert client.get(f"/api/v1/runs/{run_id}/log", headers=tokens.auth("bob")).status_code == 403
    own = client.get(f"/api/v1/runs/{run_id}/log", headers=tokens.auth("alice"))
    assert own.status_code == 200 and own.headers["content-type"].startswith("text/plain")
    assert client.get(f"/api/v1/runs/{run_id}/log", headers=tokens.auth("admin")).status_code == 200
    assert client.get(f"/api/v1/runs/{run_id}/series").status_code == 404
    missing = client.get(f"/api/v1/runs/{run_id}/artifacts/recording")
    assert missing.status_code == 404 and "no recording" in missing.json()["detail"]
    bad_kind = client.get(f"/api/v1/runs/{run_id}/artifacts/passwords")
    assert bad_kind.status_code == 404 and "mesh" in bad_kind.json()["detail"]
    assert client.get("/api/v1/runs/424242").status_code == 404


def test_leaderboard_is_empty_without_results(client: TestClient) -> None:
    board = client.get("/api/v1/leaderboard", params={"preset": "default"}).json()
    assert board.pop("benchmark_version") == current_version()
    assert "time_to_90_coverage_s" in {m["key"] for m in board.pop("metrics")}
    assert board.pop("statistics")["resamples"] == 2000  # how intervals would be made
    assert board == {"preset": "default", "split": "public", "heldout_generation": None,
                     "areas": [], "overall": [], "entries": []}
    versions = client.get("/api/v1/benchmark-versions").json()
    assert versions == {"current": current_version(), "preset": None, "versions": []}


def test_front_page_escapes_what_it_shows(client: TestClient, tokens: Any,
                                          sessions: sessionmaker[Session]) -> None:
    from server.models import User

    with sessions() as s:
        s.execute(update(User).where(User.name == "alice").values(
            name="<script>alert(1)</script>"))
        s.commit()
    _submit(client, tokens.auth("alice"), runs=1)
    page = client.get("/")
    assert page.status_code == 200 and page.headers["content-type"].startswith("text/html")
    assert "<script>alert(1)</script>" not in page.text
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in page.text
    assert "No results yet." in page.text
