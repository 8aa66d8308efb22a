"""Per-user quotas answer 429 with a message; platform failures do not count."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from fastapi.testclient import TestClient
from sqlalchemy import update
from sqlalchemy.orm import Session, sessionmaker

from server.app import create_app
from server.models import FailureKind, Run, RunState
from server.settings import Settings

JOB = {"planner": "classic", "areas": ["maze"], "runs": 1, "seconds": 10}


def _client(settings: Settings, **quotas: int) -> TestClient:
    return TestClient(create_app(settings.model_copy(update=quotas), sweeper=False,
                                 sync_areas=False))


def test_jobs_per_day(settings: Settings, sessions: sessionmaker[Session], tokens: Any) -> None:
    with _client(settings, quota_jobs_per_day=2) as client:
        for _ in range(2):
            assert client.post("/api/v1/jobs", json=JOB,
                               headers=tokens.auth("alice")).status_code == 201
        refused = client.post("/api/v1/jobs", json=JOB, headers=tokens.auth("alice"))
        assert refused.status_code == 429 and "2 jobs per day" in refused.json()["detail"]
        # Someone else is not affected, nor is an admin.
        assert client.post("/api/v1/jobs", json=JOB, headers=tokens.auth("bob")).status_code == 201
        assert client.post("/api/v1/jobs", json=JOB,
                           headers=tokens.auth("admin")).status_code == 201
        # A job that failed for a platform reason gives its slot back.
        with sessions() as s:
            s.execute(update(Run).where(Run.job_id == 1).values(
                status=RunState.FAILED.value, failure_kind=FailureKind.PLATFORM.value))
            s.commit()
        assert client.post("/api/v1/jobs", json=JOB,
                           headers=tokens.auth("alice")).status_code == 201


def test_concurrent_runs(settings: Settings, sessions: sessionmaker[Session], tokens: Any,
                         tmp_path: Path) -> None:
    with _client(settings, quota_concurrent_runs=3) as client:
        assert client.post("/api/v1/jobs", json={**JOB, "runs": 2},
                           headers=tokens.auth("alice")).status_code == 201
        refused = client.post("/api/v1/jobs", json={**JOB, "runs": 2},
                              headers=tokens.auth("alice"))
        assert refused.status_code == 429
        assert "at most 3 queued or running runs" in refused.json()["detail"]
        assert client.post("/api/v1/jobs", json=JOB,
                           headers=tokens.auth("alice")).status_code == 201
        # Finished runs free their slots.
        client.post("/api/v1/jobs/1/cancel", headers=tokens.auth("alice"))
        assert client.post("/api/v1/jobs", json={**JOB, "runs": 2},
                           headers=tokens.auth("alice")).status_code == 201
