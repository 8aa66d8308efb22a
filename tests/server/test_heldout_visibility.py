"""Nothing of a held-out scene reaches anyone but an admin: every route of the app (the API,
the website, the replay link), enumerated from the app itself, is asked about a held-out area,
its run, job and group, anonymously and with a non-admin token (the owner of the held-out
job); no answer and no log line carries the area's family, seed, statistics, content hash,
files, log or record. An admin's answers do carry them (so the probes would see a leak)."""

from __future__ import annotations

import logging
import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from fastapi import FastAPI
from fastapi.testclient import TestClient
from sqlalchemy.orm import Session, sessionmaker

from server.db import session_scope
from server.heldout import SEED_KEY, ensure_heldout_areas
from server.models import Artifact, JobGroup, User
from server.settings import Settings
from server.storage import settings_store
from tests.server.conftest import Tokens
from tests.web.stored import add_area, add_job, add_planner, add_run, current_version

CANARY = "heldout-scene-canary-7f3a"  # in the files, log, record and error of the held-out run
KINDS = ("recording", "mesh", "result", "log")


@dataclass
class World:
    area: str
    run_id: int
    public_run_id: int
    job_id: int
    group_id: int
    secrets: list[str]  # what must never reach a non-admin


def every_route(app: FastAPI) -> list[tuple[str, str]]:
    """(method, path) of every route the app serves, those left out of the schema too."""
    found: set[tuple[str, str]] = set()
    for route in app.routes:
        contexts = getattr(route, "effective_route_contexts", None)
        candidates = list(contexts()) if callable(contexts) else [route]
        for ctx in candidates:
            path, methods = getattr(ctx, "path", None), getattr(ctx, "methods", None)
            if path and methods:
                found |= {(m, path) for m in methods if m != "HEAD"}
    return sorted(found)


def _store_file(settings: Settings, key: str, tmp: Path, text: str) -> str:
    source = tmp / key.replace("/", "-")
    source.write_text(text)
    return settings_store(settings).put(key, source).location


@pytest.fixture
def world(settings: Settings, sessions: sessionmaker[Session], tokens: Tokens,
          tmp_path: Path) -> Iterator[World]:
    with session_scope(sessions) as s:
        alice = s.query(User).filter_by(name="alice").one()
        (area,) = ensure_heldout_areas(s, settings.heldout_key, current_version(), ["maze"])
        area.stats = {**area.stats, "canary": CANARY}
        public = add_area(s, "maze")
        planner = add_planner(s, "probe-planner")
        group = JobGroup(user_id=alice.id, name="suite", preset="default", runs_per_area=1,
                         request_hash="0" * 64)
        s.add(group)
        s.flush()
        job = add_job(s, alice, planner)
        job.group_id = group.id
        run = add_run(s, job, area, 0, coverage=0.5, fscore=0.4, volume=[0.0, 5.0],
                      recall=[0.3], log=f"flying {CANARY}")
        run.error = f"crashed near {CANARY}"
        assert run.result is not None
        run.result.record = {"area": {"name": area.name, "sha256": area.content_hash},
                             "note": CANARY}
        s.query(Artifact).filter_by(run_id=run.id).delete()
        for kind in KINDS:
            location = _store_file(settings, f"runs/{run.id}/{kind}", tmp_path, CANARY)
            s.add(Artifact(run_id=run.id, kind=kind, location=location, size_bytes=len(CANARY),
                           sha256="b" * 64, content_type="application/octet-stream"))
        public_run = add_run(s, add_job(s, alice, planner), public, 0, coverage=0.6, fscore=0.5,
                             volume=[0.0, 6.0], recall=[0.4])
        yield_world = World(area.name, run.id, public_run.id, job.id, group.id,
                            [CANARY, area.content_hash, str(area.stats[SEED_KEY])])
    yield yield_world


def _fill(path: str, world: World, kind: str) -> str:
    values = {"run_id": str(world.run_id), "job_id": str(world.job_id),
              "group_id": str(world.group_id), "name": world.area, "kind": kind}
    return re.sub(r"\{(\w+)(:[^}]*)?\}", lambda m: values.get(m.group(1), "probe-planner-v1"), path)


def _probe(client: TestClient, world: World, headers: dict[str, str]) -> list[tuple[str, Any]]:
    """Every route asked about the held-out things; (request, answer text) of each."""
    answers = []
    app: Any = client.app
    for method, path in every_route(app):
        if path.startswith("/static"):
            continue
        kinds = KINDS if "{kind}" in path else ("",)
        for kind in kinds:
            url = _fill(path, world, kind)
            params = {"area": world.area, "split": "heldout"} if "leaderboard" in url or \
                "curves" in url else {"area": world.area}
            response = client.request(method, url, headers=headers, params=params,
                                      follow_redirects=False)
            answers.append((f"{method} {url} -> {response.status_code}",
                            response.text + " " + str(dict(response.headers))))
    return answers


def test_no_route_shows_a_heldout_scene_to_a_non_admin(
        client: TestClient, world: World, tokens: Tokens,
        caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.DEBUG)
    probes = []
    for headers in ({}, tokens.auth("alice")):
        probes += _probe(client, world, headers)
    assert len(probes) >= 40  # the API's and the website's routes
    for request, text in probes:
        for secret in world.secrets:
            assert secret not in text, (request, secret)
    for secret in world.secrets:
        assert secret not in caplog.text
    # The same probes with an admin's token find every secret: they reach where a leak would be.
    seen_by_admin = " ".join(text for _, text in _probe(client, world, tokens.auth("admin")))
    for secret in world.secrets:
        assert secret in seen_by_admin, secret


def test_an_admin_sees_the_scene_and_everyone_its_metrics(
        client: TestClient, world: World, tokens: Tokens) -> None:
    admin, alice = tokens.auth("admin"), tokens.auth("alice")
    area = client.get(f"/api/v1/areas/{world.area}", headers=admin).json()
    assert area["split"] == "heldout" and area["stats"]["family"] == "maze"
    assert str(area["stats"][SEED_KEY]) in world.secrets
    assert client.get(f"/api/v1/areas/{world.area}", headers=alice).status_code == 404
    assert world.area in {a["name"] for a in client.get("/api/v1/areas", headers=admin).json()}
    assert world.area not in {a["name"] for a in client.get("/api/v1/areas").json()}
    for kind in ("recording", "mesh", "result"):
        url = f"/api/v1/runs/{world.run_id}/artifacts/{kind}"
        assert client.get(url, headers=admin).text == CANARY
        assert client.get(url, headers=alice).status_code == 404
    assert CANARY in client.get(f"/api/v1/runs/{world.run_id}/log", headers=admin).text
    assert client.get(f"/api/v1/runs/{world.run_id}/log", headers=alice).status_code == 403
    # Everyone sees the run's metrics, under the area's opaque name and its generation.
    run = client.get(f"/api/v1/runs/{world.run_id}").json()
    assert (run["area"], run["split"], run["heldout_generation"]) == (world.area, "heldout", 1)
    assert run["result"]["coverage"] == 0.5 and run["result"]["record"] is None
    assert run["artifacts"] == [] and CANARY not in (run["error"] or "")
    assert client.get(f"/api/v1/runs/{world.run_id}/series").status_code == 200
    # A public run keeps its files and its replay.
    public = client.get(f"/api/v1/runs/{world.public_run_id}").json()
    assert public["split"] == "public" and public["artifacts"]
    assert client.get(f"/runs/{world.run_id}/replay", follow_redirects=False).status_code == 404
    page = client.get(f"/runs/{world.run_id}").text
    assert "A held-out run (generation 1)" in page and "Held-out runs publish no files" in page
    assert "Open 3D replay" not in page
