"""Every route that changes something demands a token; tokens are hashed at rest and never
logged; rate limits, CORS, headers and download types are strict."""

from __future__ import annotations

import logging
import re
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import select, text
from sqlalchemy.orm import Session, sessionmaker

from server.app import create_app
from server.db import session_scope
from server.models import ApiToken, Artifact, Job, Run, User
from server.settings import Settings

MUTATING = {"POST", "PUT", "PATCH", "DELETE"}


def _concrete(path: str) -> str:
    return re.sub(r"\{[^}]+\}", "1", path)


def test_every_mutating_route_demands_a_token(client: TestClient) -> None:
    # Every route of the app, as its OpenAPI schema lists them.
    paths = client.get("/openapi.json").json()["paths"]
    routes = [(method.upper(), path) for path, ops in paths.items() for method in ops
              if method.upper() in MUTATING]
    assert len(routes) >= 5  # jobs, cancel, rerun, areas, planners
    for method, path in routes:
        for headers in ({}, {"Authorization": "Bearer not-a-token"}):
            response = client.request(method, _concrete(path), headers=headers)
            assert response.status_code == 401, (method, path, response.text)
            assert response.json()["detail"]


def test_tokens_are_hashed_at_rest(sessions: sessionmaker[Session], token: str,
                                   settings: Settings) -> None:
    with sessions() as s:
        rows = s.scalars(select(ApiToken)).all()
        dump = " ".join(str(v) for row in s.execute(text("SELECT * FROM api_tokens"))
                        for v in row)
    assert len(rows) == 1 and rows[0].token_hash != token
    assert token not in dump and token[8:] not in dump
    assert len(rows[0].token_hash) == 64


def test_tokens_and_secrets_never_reach_the_logs(client: TestClient, token: str,
                                                 settings: Settings,
                                                 caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.DEBUG)
    headers = {"Authorization": f"Bearer {token}"}
    client.post("/api/v1/jobs", json={"planner": "classic", "areas": ["maze"], "runs": 1,
                                      "seconds": 5}, headers=headers)
    client.post("/api/v1/jobs", json={"planner": "nope", "areas": ["maze"]}, headers=headers)
    client.get("/api/v1/jobs/999", headers=headers)
    assert token not in caplog.text and settings.secret_key not in caplog.text


def test_write_rate_limit(settings: Settings, sessions: sessionmaker[Session],
                          token: str) -> None:
    strict = settings.model_copy(update={"rate_limit_writes_per_minute": 6.0,
                                         "rate_limit_burst": 3})
    with TestClient(create_app(strict, sweeper=False, sync_areas=False)) as client:
        headers = {"Authorization": f"Bearer {token}"}
        answers = [client.post("/api/v1/jobs", json={"planner": "nope", "areas": ["maze"]},
                               headers=headers) for _ in range(5)]
        codes = [a.status_code for a in answers]
        assert codes[:3] == [422, 422, 422] and codes[3:] == [429, 429]
        assert int(answers[-1].headers["Retry-After"]) >= 1
        assert "rate limit" in answers[-1].json()["detail"]
        assert client.get("/api/v1/jobs").status_code == 200  # reads are not limited


def test_repeated_bad_tokens_are_slowed_down(settings: Settings,
                                             sessions: sessionmaker[Session]) -> None:
    strict = settings.model_copy(update={"rate_limit_auth_failures_per_minute": 6.0,
                                         "rate_limit_burst": 3})
    with TestClient(create_app(strict, sweeper=False, sync_areas=False)) as client:
        bad = {"Authorization": "Bearer guess"}
        codes = [client.post("/api/v1/jobs/1/cancel", headers=bad).status_code
                 for _ in range(6)]
    assert codes[:3] == [401, 401, 401] and 429 in codes[3:]


def test_cors_is_closed_by_default_and_exact_when_configured(
    client: TestClient, settings: Settings, sessions: sessionmaker[Session],
) -> None:
    preflight = {"Origin": "https://evil.example", "Access-Control-Request-Method": "POST"}
    answer = client.options("/api/v1/jobs", headers=preflight)
    assert "access-control-allow-origin" not in answer.headers
    allowed = settings.model_copy(update={"cors_origins": ["https://lab.example"]})
    with TestClient(create_app(allowed, sweeper=False, sync_areas=False)) as open_client:
        evil = open_client.get("/api/v1/planners", headers={"Origin": "https://evil.example"})
        assert "access-control-allow-origin" not in evil.headers
        lab = open_client.get("/api/v1/planners", headers={"Origin": "https://lab.example"})
        assert lab.headers["access-control-allow-origin"] == "https://lab.example"
        assert "access-control-allow-credentials" not in lab.headers


def test_security_headers_everywhere(client: TestClient) -> None:
    for path in ("/healthz", "/api/v1/planners", "/api/v1/jobs/12345", "/"):
        headers = client.get(path).headers
        assert headers["x-content-type-options"] == "nosniff"
        assert headers["x-frame-options"] == "DENY"


def test_downloads_are_attachments_of_inert_types(client: TestClient,
                                                  sessions: sessionmaker[Session],
                                                  settings: Settings) -> None:
    store = Path(settings.artifacts.removeprefix("file://"))
    (store / "runs/1").mkdir(parents=True)
    (store / "runs/1/mesh.ply").write_text("<html><script>alert(1)</script></html>")
    with session_scope(sessions) as s:
        from server.catalog import ensure_area, sync_builtin_planners

        sync_builtin_planners(s)
        user = User(name="u")
        s.add(user)
        s.flush()
        area = ensure_area(s, "maze")
        from server.catalog import find_planner

        job = Job(user_id=user.id, planner_id=find_planner(s, "classic").id, preset="default",
                  runs_per_area=1, request_hash="x")
        s.add(job)
        s.flush()
        run = Run(job_id=job.id, area_id=area.id, seed=0, preset="default", seconds=1.0)
        s.add(run)
        s.flush()
        s.add(Artifact(run_id=run.id, kind="mesh", location="runs/1/mesh.ply", size_bytes=40,
                       sha256="0" * 64, content_type="text/html"))
    answer = client.get(f"/api/v1/runs/{run.id}/artifacts/mesh")
    assert answer.status_code == 200
    assert answer.headers["content-type"] == "application/octet-stream"
    assert answer.headers["content-disposition"].startswith("attachment;")
    assert answer.headers["x-content-type-options"] == "nosniff"
    traversal = client.get(f"/api/v1/runs/{run.id}/artifacts/..%2F..%2Fetc%2Fpasswd")
    assert traversal.status_code == 404


def test_production_refuses_the_development_secret() -> None:
    from pydantic import ValidationError

    with pytest.raises(ValidationError, match="FLYBO_SECRET_KEY"):
        Settings(environment="production")
    assert Settings(environment="production", secret_key="x" * 40).environment == "production"
