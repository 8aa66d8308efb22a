"""The viewer starts and serves viser's client; the website's replay link redirects to it."""

from __future__ import annotations

from pathlib import Path

import httpx
import pytest
from fastapi import FastAPI
from fastapi.testclient import TestClient

from server.settings import Settings
from tests.replay.conftest import ServiceDb, free_port
from web.replay.app import start_viewer
from web.replay.routes import router, viewer_url
from web.replay.source import RunLookupError


def test_viewer_serves_its_client_and_stops(run_dir: Path, tmp_path: Path) -> None:
    port = free_port()
    handle = start_viewer(Settings(data_dir=tmp_path), "127.0.0.1", port,
                          recording=run_dir / "recording.npz")
    try:
        assert handle.port == port
        page = httpx.get(f"{handle.url}/", timeout=10.0)
        assert page.status_code == 200
        assert "<title>Viser</title>" in page.text
        # The page keeps working with a run in its query: the client ignores unknown keys.
        assert httpx.get(f"{handle.url}/?run=3", timeout=10.0).status_code == 200
        # The recording given at start is loaded before the first tab connects.
        run = handle.app.cache.get(handle.app.default_key or "")
        assert run.area.name == "maze"
    finally:
        handle.stop()
    with pytest.raises(httpx.TransportError):
        httpx.get(f"{handle.url}/", timeout=2.0)


def test_viewer_refuses_a_bad_recording(tmp_path: Path) -> None:
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"nothing")
    with pytest.raises(RunLookupError):
        start_viewer(Settings(data_dir=tmp_path), "127.0.0.1", free_port(), recording=bad)


def test_page_queries_choose_the_runs(run_dir: Path, tmp_path: Path) -> None:
    handle = start_viewer(Settings(data_dir=tmp_path), "127.0.0.1", free_port(),
                          recording=run_dir / "recording.npz")
    try:
        app = handle.app
        assert app.initial_keys({}) == (app.default_key, None)
        assert app.initial_keys({"run": "12"}) == ("run:12", None)
        assert app.initial_keys({"run": "12", "compare": "4"}) == ("run:12", "run:4")
        assert app.initial_keys({"run": "x; drop"}) == (app.default_key, None)
        assert app.key_for(" 7 ") == "run:7"
        assert app.key_for(str(run_dir / "recording.npz")) == app.default_key
        with pytest.raises(RunLookupError):
            app.key_for(str(tmp_path / "nothing.npz"))
    finally:
        handle.stop()


class _WithViewer(Settings):
    """Settings once the service has its `viewer_url` setting."""

    viewer_url: str = "https://replay.example.org/"


def _site(db: ServiceDb, settings: Settings | None = None) -> TestClient:
    app = FastAPI()
    app.state.settings = settings or db.settings
    app.state.sessions = db.sessions
    app.include_router(router)
    return TestClient(app)


def test_replay_link_redirects_to_the_viewer(service_db: ServiceDb) -> None:
    first, _ = service_db.with_recording
    answer = _site(service_db).get(f"/runs/{first}/replay", follow_redirects=False)
    assert answer.status_code == 307
    assert answer.headers["location"] == f"http://127.0.0.1:8080/?run={first}"
    public = _WithViewer(data_dir=service_db.settings.data_dir)
    answer = _site(service_db, public).get(f"/runs/{first}/replay", follow_redirects=False)
    assert answer.headers["location"] == f"https://replay.example.org/?run={first}"
    assert viewer_url(public, 5) == "https://replay.example.org/?run=5"


def test_replay_link_of_a_missing_run_or_recording_is_404(service_db: ServiceDb) -> None:
    client = _site(service_db)
    missing = client.get("/runs/999/replay", follow_redirects=False)
    assert missing.status_code == 404
    assert missing.json() == {"detail": "run 999 does not exist"}
    queued = client.get(f"/runs/{service_db.without_recording}/replay", follow_redirects=False)
    assert queued.status_code == 404
    assert "no recording" in queued.json()["detail"]
