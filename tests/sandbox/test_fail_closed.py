"""Uploaded code runs only in full isolation: where the probe finds less, the upload is refused
(503) and the run fails as the platform's fault, unless the operator allowed the insecure
fallback, which is then logged. A failed probe is probed again, never kept."""

from __future__ import annotations

import io
import logging
import re
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import func, select

from server.app import create_app as create_api
from server.db import make_engine, make_session_factory, session_scope
from server.migrate import upgrade
from server.models import PlannerRow, Run
from server.planner_package import CheckOutcome, CheckUnavailableError, load_package
from server.security import create_token
from server.settings import Settings
from worker.sandbox import isolation
from worker.sandbox.dry_run import dry_run
from worker.sandbox.isolation import Isolation, SandboxUnavailableError
from worker.sandbox.proxy import SandboxedPlanner, SandboxError

GOOD = b'''
import numpy as np
from planners.api import Plan, Planner


class Hover(Planner):
    def plan(self, obs):
        return Plan(np.array([[*obs.pose.position, obs.pose.yaw]]))
'''

FULL = Isolation("/usr/bin/bwrap", True, Path("/sys/fs/cgroup/pids/x"),
                 Path("/sys/fs/cgroup/memory/x"))
PARTIAL = {
    "no bubblewrap": replace(FULL, bwrap=None, namespaces=False,
                             notes=["bubblewrap (bwrap) is not installed"]),
    "no namespaces": replace(FULL, namespaces=False, notes=["bubblewrap cannot create"]),
    "no pids cgroup": replace(FULL, cgroup_pids=None, notes=["no writable pids cgroup"]),
    "no memory cgroup": replace(FULL, cgroup_memory=None, notes=["no writable memory cgroup"]),
}


@pytest.fixture(autouse=True)
def _secure(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("FLYBO_SANDBOX_ALLOW_INSECURE", raising=False)


def _partial(monkeypatch: pytest.MonkeyPatch, which: str = "no namespaces") -> None:
    monkeypatch.setattr(isolation, "probe", lambda: PARTIAL[which])


def _code(tmp_path: Path) -> Path:
    code = tmp_path / "code"
    code.mkdir(exist_ok=True)
    (code / "planner.py").write_bytes(GOOD)
    return code


def test_full_means_bubblewrap_namespaces_and_both_cgroups() -> None:
    assert FULL.full
    assert not any(iso.full for iso in PARTIAL.values())


def test_a_failed_probe_is_probed_again_and_a_full_one_kept(
        monkeypatch: pytest.MonkeyPatch) -> None:
    answers = [PARTIAL["no pids cgroup"], PARTIAL["no namespaces"], FULL, PARTIAL["no bubblewrap"]]
    calls: list[Isolation] = []

    def fake() -> Isolation:
        calls.append(answers[len(calls)])
        return calls[-1]

    monkeypatch.setattr(isolation, "_probe", fake)
    monkeypatch.setattr(isolation, "_full_isolation", None)
    assert isolation.probe() is answers[0]
    assert isolation.probe() is answers[1]  # probed again, not the cached failure
    assert isolation.probe() is FULL
    assert isolation.probe() is FULL and len(calls) == 3  # a full result is kept


@pytest.mark.parametrize("which", sorted(PARTIAL))
def test_uploaded_code_is_refused_without_full_isolation(
        which: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    _partial(monkeypatch, which)
    with pytest.raises(SandboxUnavailableError, match=re.escape(PARTIAL[which].notes[0])) as caught:
        SandboxedPlanner(code=_code(tmp_path))
    # Not a SandboxError: that is the planner's failure, this one is the platform's.
    assert not isinstance(caught.value, SandboxError)
    assert "docs/sandbox.md" in str(caught.value)


def test_the_insecure_setting_runs_it_and_says_so_loudly(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture) -> None:
    _partial(monkeypatch)
    monkeypatch.setenv("FLYBO_SANDBOX_ALLOW_INSECURE", "1")
    with (caplog.at_level(logging.ERROR, logger="worker.sandbox.isolation"),
          SandboxedPlanner(code=_code(tmp_path)) as planner):
        assert planner.iso is PARTIAL["no namespaces"]
    assert any(r.levelno == logging.ERROR and "INSECURE" in r.getMessage()
               and "FLYBO_SANDBOX_ALLOW_INSECURE" in r.getMessage() for r in caplog.records)
    monkeypatch.setenv("FLYBO_SANDBOX_ALLOW_INSECURE", "0")
    with pytest.raises(SandboxUnavailableError):
        SandboxedPlanner(code=_code(tmp_path))


def test_built_in_planners_need_no_full_isolation(monkeypatch: pytest.MonkeyPatch) -> None:
    _partial(monkeypatch, "no bubblewrap")
    with SandboxedPlanner(builtin="classic") as planner:  # the project's own code
        assert planner.iso is PARTIAL["no bubblewrap"]


def test_the_dry_run_is_unavailable_not_failed(monkeypatch: pytest.MonkeyPatch) -> None:
    _partial(monkeypatch, "no memory cgroup")
    with pytest.raises(CheckUnavailableError, match="no writable memory cgroup"):
        dry_run(load_package("planner.py", GOOD))


# -- through the service -----------------------------------------------------------------------

@pytest.fixture
def service(tmp_path: Path) -> Iterator[tuple[Settings, Any]]:
    settings = Settings(data_dir=tmp_path / "data",
                        database_url=f"sqlite:///{tmp_path / 'flybo.sqlite'}")
    engine = make_engine(settings.db_url)
    upgrade(engine)
    sessions = make_session_factory(engine)
    with session_scope(sessions) as session:
        token = create_token(session, "alice", settings.secret_key)
    yield settings, (sessions, {"Authorization": f"Bearer {token}"})
    engine.dispose()


def _upload(client: TestClient, headers: dict[str, str]) -> Any:
    return client.post("/api/v1/planners", headers=headers,
                       files={"file": ("planner.py", io.BytesIO(GOOD))}, data={"name": "hover"})


def test_the_upload_is_refused_with_503(service: tuple[Settings, Any],
                                        monkeypatch: pytest.MonkeyPatch) -> None:
    settings, (sessions, headers) = service
    _partial(monkeypatch, "no pids cgroup")
    with TestClient(create_api(settings, sweeper=False, sync_areas=False,
                               planner_check=dry_run)) as client:
        response = _upload(client, headers)
    assert response.status_code == 503, response.text
    assert "sandbox is not available" in response.json()["detail"]
    assert "no writable pids cgroup" in response.json()["detail"]
    with sessions() as s:
        assert s.scalar(select(func.count(PlannerRow.id)).where(
            PlannerRow.builtin.is_(False))) == 0


@pytest.mark.slow  # builds the maze's ground truth where it is not cached
def test_the_run_fails_as_the_platform_s_fault(service: tuple[Settings, Any],
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    from worker.runner import execute_run

    settings, (sessions, headers) = service
    passed = CheckOutcome(True, "accepted without a dry run (test)", 0.0)
    with TestClient(create_api(settings, sweeper=False, sync_areas=False,
                               planner_check=lambda package: passed)) as client:
        assert _upload(client, headers).status_code == 201
        job = client.post("/api/v1/jobs", headers=headers, json={
            "planner": "hover-v1", "areas": ["maze"], "runs": 1, "seconds": 5}).json()
    run_id = job["runs"][0]["id"]
    _partial(monkeypatch, "no namespaces")
    assert execute_run(run_id, settings) == "failed"
    with sessions() as s:
        run = s.get(Run, run_id)
        assert run is not None and run.status == "failed"
        assert run.failure_kind == "platform"
        assert run.error is not None and "sandbox is not available" in run.error
