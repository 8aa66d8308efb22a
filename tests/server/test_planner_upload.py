"""Uploading planners over the API: checks, dry run, versions, and a run to the leaderboard."""

from __future__ import annotations

import io
import zipfile
from typing import Any

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import func, select
from sqlalchemy.orm import Session, sessionmaker

from server.app import create_app as create_api
from server.models import PlannerRow, Run
from server.settings import Settings
from worker.runner import execute_run

GOOD = b'''
import numpy as np
from planners.api import Plan, Planner


class Spinner(Planner):
    """Turns in place a quarter turn at a time."""

    def plan(self, obs):
        p = obs.pose.position
        return Plan(np.array([[p[0], p[1], p[2], obs.pose.yaw + 1.5]]), horizon_s=0.0)
'''
RAISES = GOOD.replace(b"p = obs.pose.position", b"raise ValueError('no idea')")


def _zip(entries: dict[str, bytes], *, symlink: str | None = None) -> bytes:
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
        for name, data in entries.items():
            archive.writestr(name, data)
        if symlink is not None:
            info = zipfile.ZipInfo(symlink)
            info.external_attr = 0o120777 << 16
            archive.writestr(info, "/etc/passwd")
    return buffer.getvalue()


def _upload(client: TestClient, headers: dict[str, str], filename: str, data: bytes,
            name: str = "spinner") -> Any:
    return client.post("/api/v1/planners", headers=headers,
                       files={"file": (filename, io.BytesIO(data))},
                       data={"name": name, "description": "turns <b>in place</b>"})


def _planner_rows(sessions: sessionmaker[Session]) -> int:
    with sessions() as s:
        return s.scalar(select(func.count(PlannerRow.id)).where(
            PlannerRow.builtin.is_(False))) or 0


@pytest.mark.parametrize(("filename", "data", "status", "needle"), [
    ("planner.txt", GOOD, 422, "unsupported file type"),
    ("planner.py", b"def broken(:\n", 422, "syntax error"),
    ("planner.py", b"\xff\xfe", 422, "not UTF-8"),
    ("code.zip", b"not a zip", 422, "not a valid zip"),
    ("code.zip", _zip({"other.py": GOOD}), 422, "no planner.py"),
    ("code.zip", _zip({"planner.py": GOOD, "../evil.py": b"x = 1"}), 422, "'..'"),
    ("code.zip", _zip({"planner.py": GOOD, "/etc/evil.py": b"x = 1"}), 422, "absolute"),
    ("code.zip", _zip({"planner.py": GOOD, "fast.so": b"\x7fELF"}), 422, "compiled"),
    ("code.zip", _zip({"planner.py": GOOD, "cache.pyc": b"\x00"}), 422, "compiled"),
    ("code.zip", _zip({"planner.py": GOOD}, symlink="link.py"), 422, "links"),
    ("code.zip", _zip({"planner.py": GOOD, "zeros.txt": b"\0" * (11 * 1024 * 1024)}), 422,
     "unpacks to"),
    ("code.zip", _zip({f"m{i}.py": b"x = 1" for i in range(201)} | {"planner.py": GOOD}), 422,
     "too many files"),
    ("planner.py", RAISES, 422, "no idea"),
    ("planner.py", b"x = 1\n", 422, "defines no class deriving from"),
    ("planner.py", b"from planners.api import Planner\nclass A(Planner): pass\n"
     b"class B(Planner): pass\n", 422, "exactly one Planner subclass"),
])
def test_refused_uploads_store_nothing(
    client: TestClient, tokens: Any, sessions: sessionmaker[Session], filename: str,
    data: bytes, status: int, needle: str,
) -> None:
    response = _upload(client, tokens.auth("alice"), filename, data)
    assert response.status_code == status, response.text
    assert needle in response.json()["detail"]
    assert _planner_rows(sessions) == 0


def test_size_limit_and_names(client: TestClient, tokens: Any,
                              sessions: sessionmaker[Session]) -> None:
    big = _upload(client, tokens.auth("alice"), "planner.py", b"#" * (2 * 1024 * 1024))
    assert big.status_code == 413 and "too large" in big.json()["detail"]
    builtin = _upload(client, tokens.auth("alice"), "planner.py", GOOD, name="classic")
    assert builtin.status_code == 409 and "built-in" in builtin.json()["detail"]
    assert _upload(client, {}, "planner.py", GOOD).status_code == 401
    assert _planner_rows(sessions) == 0


def test_the_api_alone_checks_uploads_but_cannot_dry_run_them(
    settings: Settings, tokens: Any, sessions: sessionmaker[Session],
) -> None:
    """`server.app.create_app` without a planner check (no sandbox): the static checks still
    refuse bad code, good code is refused as unverifiable, and nothing is stored."""
    with TestClient(create_api(settings, sweeper=False, sync_areas=False)) as api:
        bad = _upload(api, tokens.auth("alice"), "planner.py", b"x = 1\n")
        assert bad.status_code == 422 and "defines no class" in bad.json()["detail"]
        good = _upload(api, tokens.auth("alice"), "planner.py", GOOD)
        assert good.status_code == 503 and "sandbox" in good.json()["detail"]
    assert _planner_rows(sessions) == 0


def test_upload_versions_and_a_run_to_the_leaderboard(
    client: TestClient, tokens: Any, sessions: sessionmaker[Session], settings: Settings,
) -> None:
    first = _upload(client, tokens.auth("alice"), "planner.py", GOOD)
    assert first.status_code == 201, first.text
    body = first.json()
    assert (body["id"], body["builtin"], body["owner"]) == ("spinner-v1", False, "alice")
    assert body["config"]["check"]["passed"] and "dry run" in body["config"]["check"]["output"]
    assert "code" not in body["config"] and len(body["code_hash"]) == 64
    public = client.get("/api/v1/planners/spinner").json()
    assert "output" not in public["config"]["check"]
    stolen = _upload(client, tokens.auth("bob"), "planner.py", GOOD)
    assert stolen.status_code == 403 and "another user" in stolen.json()["detail"]
    second = _upload(client, tokens.auth("alice"), "code.zip",
                     _zip({"planner.py": GOOD, "README.md": b"# spinner"}))
    assert second.status_code == 201 and second.json()["id"] == "spinner-v2"
    assert client.get("/api/v1/planners/spinner-v1").json()["version"] == 1  # kept

    job = client.post("/api/v1/jobs", headers=tokens.auth("alice"), json={
        "planner": "spinner-v1", "areas": ["maze"], "runs": 1, "seconds": 12}).json()
    run_id = job["runs"][0]["id"]
    assert execute_run(run_id, settings) == "succeeded"
    with sessions() as s:
        run = s.get(Run, run_id)
        assert run is not None and run.status == "succeeded"
    board = client.get("/api/v1/leaderboard").json()
    entry = board["entries"][0]
    assert (entry["planner"], entry["builtin"], entry["runs"]) == ("spinner-v1", False, 1)
