"""The insecure sandbox fallback (`FLYBO_SANDBOX_ALLOW_INSECURE`) is refused in production: the
settings refuse it, so no process of the service (API, worker, CLI) starts with it, and the
sandbox runs no uploaded code under such settings, whatever this machine offers."""

from __future__ import annotations

from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from pydantic import ValidationError

from server.app import create_app
from server.planner_package import CheckUnavailableError, load_package
from server.settings import Settings
from worker.sandbox import isolation
from worker.sandbox.dry_run import dry_run
from worker.sandbox.proxy import SandboxedPlanner

SECRET = "s" * 40
GOOD = b'''
import numpy as np
from planners.api import Plan, Planner


class Hover(Planner):
    def plan(self, obs):
        return Plan(np.array([[*obs.pose.position, obs.pose.yaw]]))
'''


def _settings(tmp_path: Path, environment: str) -> Settings:
    return Settings(data_dir=tmp_path / "data", environment=environment, secret_key=SECRET)


def test_the_settings_refuse_it_in_production(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("FLYBO_SANDBOX_ALLOW_INSECURE", "1")
    with pytest.raises(ValidationError) as refused:
        _settings(tmp_path, "production")
    message = str(refused.value)
    assert "FLYBO_SANDBOX_ALLOW_INSECURE" in message and "FLYBO_ENVIRONMENT=production" in message
    assert "development only" in message
    assert _settings(tmp_path, "development").sandbox_allow_insecure


@pytest.mark.parametrize(("environment", "insecure"), [
    ("development", "1"), ("production", "0"), ("production", None)])
def test_the_api_starts_otherwise(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                  environment: str, insecure: str | None) -> None:
    if insecure is None:
        monkeypatch.delenv("FLYBO_SANDBOX_ALLOW_INSECURE", raising=False)
    else:
        monkeypatch.setenv("FLYBO_SANDBOX_ALLOW_INSECURE", insecure)
    app = create_app(_settings(tmp_path, environment), sweeper=False, sync_areas=False)
    with TestClient(app) as client:
        assert client.get("/api/v1/planners").status_code == 200


def test_the_sandbox_runs_no_uploaded_code_with_it_in_production(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # Where the API was started otherwise (a worker, `flybo planners check`): refused at use,
    # as the platform's failure, even where full isolation would not need the fallback.
    monkeypatch.setenv("FLYBO_SANDBOX_ALLOW_INSECURE", "true")
    monkeypatch.setenv("FLYBO_ENVIRONMENT", "production")
    monkeypatch.setenv("FLYBO_SECRET_KEY", SECRET)
    with pytest.raises(isolation.SandboxPolicyError, match="FLYBO_ENVIRONMENT=production"):
        isolation.require_full()
    code = tmp_path / "code"
    code.mkdir()
    (code / "planner.py").write_bytes(GOOD)
    with pytest.raises(isolation.SandboxUnavailableError, match="development only"):
        SandboxedPlanner(code=code)
    with pytest.raises(CheckUnavailableError, match="FLYBO_SANDBOX_ALLOW_INSECURE"):
        dry_run(load_package("planner.py", GOOD))
    monkeypatch.setenv("FLYBO_ENVIRONMENT", "development")
    assert isolation.insecure_allowed()
