"""Uploading a building model as a new area: checked, stored, and refused clearly when bad."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import pytest
import trimesh
from fastapi.testclient import TestClient
from sqlalchemy import func, select
from sqlalchemy.orm import Session, sessionmaker

from server.app import create_app
from server.models import AreaRow, RunResult
from server.settings import Settings
from worker.runner import execute_run


@pytest.fixture(autouse=True)
def _private_folders(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("FLYBO_DATA_DIR", str(tmp_path / "data"))
    monkeypatch.setenv("FLYBO_CACHE_DIR", str(tmp_path / "cache"))


def _room_obj() -> bytes:
    """A closed 6 x 5 x 3 m box: its inside is the free space."""
    return str(trimesh.creation.box(extents=(6.0, 5.0, 3.0)).export(file_type="obj")).encode()


def _upload(client: TestClient, headers: dict[str, str], data: bytes, filename: str = "room.obj",
            **form: Any) -> Any:
    return client.post("/api/v1/areas", headers=headers,
                       files={"file": (filename, io.BytesIO(data), "application/octet-stream")},
                       data={"name": "my-room", **form})


def _areas(sessions: sessionmaker[Session]) -> int:
    with sessions() as s:
        return s.scalar(select(func.count(AreaRow.id))) or 0


def test_upload_and_read_back(client: TestClient, tokens: Any,
                              sessions: sessionmaker[Session]) -> None:
    response = _upload(client, tokens.auth("alice"), _room_obj())
    assert response.status_code == 201, response.text
    area = response.json()
    assert area["name"] == "my-room" and not area["builtin"]
    # The explorable box is the model's box plus a margin on each side.
    size = area["stats"]["bounding_volume_m"]
    assert all(m <= s <= m + 1.5 for m, s in zip((6.0, 5.0, 3.0), size, strict=True))
    assert area["stats"]["faces"] == 12
    assert client.get("/api/v1/areas/my-room").json()["content_hash"] == area["content_hash"]
    again = _upload(client, tokens.auth("bob"), _room_obj())
    assert again.status_code == 409 and "already exists" in again.json()["detail"]
    taken = client.post("/api/v1/areas", headers=tokens.auth("bob"),
                        files={"file": ("m.obj", io.BytesIO(_room_obj()))},
                        data={"name": "maze"})
    assert taken.status_code == 409
    assert _areas(sessions) == 1


@pytest.mark.parametrize(("filename", "data", "form", "status", "needle"), [
    ("room.exe", b"MZ", {}, 422, "unsupported mesh file type"),
    ("room.obj", b"this is not a mesh", {}, 422, "mesh rejected"),
    ("room.obj", b"", {}, 422, "mesh rejected"),
    ("room.obj", None, {"name": "Bad Name!"}, 422, "name"),
    ("room.obj", None, {"scale": "-1"}, 422, "scale"),
    ("room.obj", None, {"up": "w"}, 422, "up"),
])
def test_bad_uploads(client: TestClient, tokens: Any, sessions: sessionmaker[Session],
                     filename: str, data: bytes | None, form: dict[str, str], status: int,
                     needle: str) -> None:
    response = _upload(client, tokens.auth("alice"), _room_obj() if data is None else data,
                       filename, **form)
    assert response.status_code == status, response.text
    assert needle in response.json()["detail"]
    assert _areas(sessions) == 0


def test_upload_needs_a_token(client: TestClient, sessions: sessionmaker[Session]) -> None:
    assert _upload(client, {}, _room_obj()).status_code == 401
    assert _areas(sessions) == 0


def test_upload_size_limit(settings: Settings, sessions: sessionmaker[Session],
                           tokens: Any) -> None:
    small = settings.model_copy(update={"max_area_upload_mib": 0.001})
    with TestClient(create_app(small, sweeper=False, sync_areas=False)) as client:
        response = _upload(client, tokens.auth("alice"), _room_obj() * 10)
    assert response.status_code == 413 and "too large" in response.json()["detail"]
    assert _areas(sessions) == 0


def test_an_upload_is_kept_and_flown_from_the_settings_folder(
    client: TestClient, tokens: Any, settings: Settings, sessions: sessionmaker[Session],
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The route and the worker use `Settings.areas_dir`, not the areas library's default."""
    monkeypatch.setenv("FLYBO_DATA_DIR", str(tmp_path / "elsewhere"))
    assert _upload(client, tokens.auth("alice"), _room_obj()).status_code == 201
    saved = settings.areas_dir / "my-room.npz"
    assert saved.is_file() and not (tmp_path / "elsewhere").exists()
    saved.unlink()  # as on a worker's machine that never saw it: fetched from the store
    job = client.post("/api/v1/jobs", headers=tokens.auth("alice"), json={
        "planner": "classic", "areas": ["my-room"], "runs": 1, "seconds": 4}).json()
    run_id = job["runs"][0]["id"]
    assert execute_run(run_id, settings) in {"succeeded", "failed"}
    assert saved.is_file() and not (tmp_path / "elsewhere").exists()
    with sessions() as s:
        result = s.get(RunResult, run_id)
        assert result is not None and result.simulated_until_s > 0
