"""The held-out split: secret seeds and opaque names, a board per split and generation,
rotation from the CLI, job groups that add the held-out areas, and the gap on the front page."""

from __future__ import annotations

import json
import re
from collections.abc import Iterator
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from sqlalchemy.orm import Session, sessionmaker

from flybo.app import create_app
from flybo.cli import main
from server.db import session_scope
from server.heldout import (
    NAME_PREFIX,
    current_generation,
    ensure_heldout_areas,
    heldout_name,
    heldout_seed,
    rotate,
)
from server.models import AreaRow, PlannerRow, User
from server.settings import Settings
from tests.server.conftest import Tokens
from tests.web.stored import add_area, add_job, add_planner, add_run, current_version


def test_seeds_and_names_are_secret_and_opaque() -> None:
    key, other = b"k" * 32, b"o" * 32
    seed = heldout_seed(key, "v1", 1, "maze")
    assert seed == heldout_seed(key, "v1", 1, "maze") and 0 < seed < 2**63
    variants = {heldout_seed(other, "v1", 1, "maze"), heldout_seed(key, "v2", 1, "maze"),
                heldout_seed(key, "v1", 2, "maze"), heldout_seed(key, "v1", 1, "warehouse")}
    assert seed not in variants and len(variants) == 4
    name = heldout_name(key, "v1", 1, "maze")
    assert name.startswith(NAME_PREFIX) and len(name) == len(NAME_PREFIX) + 8
    assert "maze" not in name and str(seed)[:6] not in name
    assert name != heldout_name(key, "v1", 2, "maze")


def test_the_heldout_key_is_its_own_secret_or_derived_from_the_secret_key() -> None:
    a = Settings(secret_key="a" * 40)
    assert a.heldout_key != Settings(secret_key="b" * 40).heldout_key
    assert a.heldout_key != ("a" * 40).encode()
    assert Settings(heldout_secret="h" * 40).heldout_key == ("h" * 40).encode()


def _results(sessions: sessionmaker[Session], settings: Settings) -> tuple[str, str]:
    """A public and a held-out area with one run of one planner each: (public, held-out)."""
    with session_scope(sessions) as s:
        alice = s.query(User).filter_by(name="alice").one()
        public = add_area(s, "maze")
        (heldout,) = ensure_heldout_areas(s, settings.heldout_key, current_version(), ["maze"])
        planner = add_planner(s, "probe-planner", method="original")
        add_run(s, add_job(s, alice, planner), public, 0, coverage=0.8, fscore=0.5,
                volume=[0.0, 8.0], recall=[0.5])
        add_run(s, add_job(s, alice, planner), heldout, 0, coverage=0.5, fscore=0.4,
                volume=[0.0, 5.0], recall=[0.4])
        return public.name, heldout.name


def test_boards_per_split_and_generation(client: TestClient, tokens: Tokens,
                                         sessions: sessionmaker[Session],
                                         settings: Settings) -> None:
    public, first = _results(sessions, settings)
    board = client.get("/api/v1/leaderboard").json()
    assert (board["split"], board["areas"]) == ("public", [public])
    held = client.get("/api/v1/leaderboard", params={"split": "heldout"}).json()
    assert (held["split"], held["heldout_generation"], held["areas"]) == ("heldout", 1, [first])
    assert held["overall"][0]["mean_coverage"] == pytest.approx(0.5)
    with session_scope(sessions) as s:
        assert rotate(s, "a test") == 2 and current_generation(s) == 2
        (second,) = ensure_heldout_areas(s, settings.heldout_key, current_version(), ["maze"])
        assert second.name != first and second.heldout_generation == 2
    # The new generation's board holds none of the old one's results; the old board stays.
    assert client.get("/api/v1/leaderboard", params={"split": "heldout"}).json()["areas"] == []
    old = client.get("/api/v1/leaderboard", params={"split": "heldout",
                                                   "heldout_generation": 1}).json()
    assert (old["heldout_generation"], old["areas"]) == (1, [first])
    assert client.get("/api/v1/leaderboard", params={
        "split": "heldout", "heldout_generation": 3}).status_code == 404
    assert client.get("/api/v1/leaderboard", params={"heldout_generation": 1}).status_code == 422
    # No new run joins a rotated-away generation.
    answer = client.post("/api/v1/jobs", headers=tokens.auth("alice"), json={
        "planner": "classic", "areas": [first], "runs": 1, "seconds": 5})
    assert answer.status_code == 409 and "rotated" in answer.json()["detail"]


def test_the_front_page_shows_both_boards_and_the_gap(client: TestClient, tokens: Tokens,
                                                      sessions: sessionmaker[Session],
                                                      settings: Settings) -> None:
    _results(sessions, settings)
    page = client.get("/").text
    assert "id='heldout-table'" in page and "probe-planner-v1" in page
    row = page.split("id='heldout-table'")[1].split("</tr>")[1]  # after the header row
    # Held-out 50.0 %, public 80.0 %: a gap of 30.0 percentage points.
    assert re.findall(r">([0-9.]+)</td>", row)[-3:] == ["50.0", "80.0", "30.0"]
    assert ">original method</span>" in row  # what it is to its paper, as on the public board
    public = client.get("/api/v1/leaderboard").json()
    held = client.get("/api/v1/leaderboard", params={"split": "heldout"}).json()
    # The API's held-out board carries the same signal; the public board has none.
    (planner,) = held["overall"]
    assert planner["public_mean_coverage"] == pytest.approx(0.8)
    assert planner["public_gap"] == pytest.approx(0.3)
    assert all(p["public_gap"] is None for p in public["overall"])


@pytest.fixture
def maze_heldout_client(settings: Settings,
                        sessions: sessionmaker[Session]) -> Iterator[TestClient]:
    app = create_app(settings.model_copy(update={"heldout_areas": ["maze"]}), sweeper=False,
                     sync_areas=False, benchmark_version=current_version())
    with TestClient(app) as client:
        yield client


def test_a_group_adds_the_heldout_areas(maze_heldout_client: TestClient, tokens: Tokens,
                                        sessions: sessionmaker[Session],
                                        settings: Settings) -> None:
    body = {"planners": ["classic"], "areas": ["maze"], "runs": 1, "seconds": 5,
            "heldout": True}
    group = maze_heldout_client.post("/api/v1/groups", json=body,
                                     headers=tokens.auth("alice")).json()
    name = heldout_name(settings.heldout_key, current_version(), 1, "maze")
    assert group["areas"] == ["maze", name] and group["runs"] == 2
    with sessions() as s:
        row = s.query(AreaRow).filter_by(name=name).one()
        assert (row.split, row.heldout_generation, row.stats["family"]) == ("heldout", 1, "maze")
    refused = maze_heldout_client.post("/api/v1/groups", headers=tokens.auth("alice"),
                                       json={**body, "areas": ["warehouse"]})
    assert refused.status_code == 422 and "held-out counterpart" in refused.json()["detail"]


def test_rotating_from_the_cli(settings: Settings, sessions: sessionmaker[Session],
                               monkeypatch: pytest.MonkeyPatch, tmp_path: Path,
                               capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setenv("FLYBO_DATABASE_URL", settings.db_url)
    monkeypatch.setenv("FLYBO_DATA_DIR", str(tmp_path / "cli"))
    with session_scope(sessions) as s:
        ensure_heldout_areas(s, settings.heldout_key, current_version(), ["maze"])
    main(["heldout", "rotate", "--note", "seeds seen in a paper"])
    assert "held-out generation 1 -> 2" in capsys.readouterr().out
    main(["heldout", "list"])
    listed = capsys.readouterr().out
    assert "current held-out generation: 2" in listed and "family maze" in listed
    with sessions() as s:
        assert current_generation(s) == 2


def test_a_worker_flies_the_heldout_area(sessions: sessionmaker[Session],
                                         settings: Settings) -> None:
    from server.catalog import sync_builtin_planners
    from server.jobs import create_job
    from server.models import Run, RunResult
    from server.schemas import JobCreate
    from worker.runner import execute_run

    with session_scope(sessions) as s:
        sync_builtin_planners(s)
        user = User(name="carol")
        s.add(user)
        s.flush()
        (area,) = ensure_heldout_areas(s, settings.heldout_key, current_version(), ["maze"])
        name, content_hash = area.name, area.content_hash
        created = create_job(s, settings, user, JobCreate(planner="classic", areas=[name],
                                                          runs=1, seconds=30.0))
    ((run_id, _),) = created.runs
    assert execute_run(run_id, settings) == "succeeded"
    with sessions() as s:
        run, result = s.get(Run, run_id), s.get(RunResult, run_id)
        assert run is not None and result is not None and result.record is not None
        # The scene flown is the held-out layout (the row's hash), under its opaque name; the
        # record and the log name neither its family nor its seed.
        assert result.record["area"] == {"name": name, "generator": None,
                                         "sha256": content_hash}
        seed = str(run.area.stats["layout_seed"])
        assert seed not in json.dumps(result.record) and seed not in run.log_tail
        assert 0 < result.coverage <= 1


def test_baseline_datasets_leave_the_heldout_areas_out(sessions: sessionmaker[Session],
                                                       settings: Settings,
                                                       tokens: Tokens) -> None:
    from server.baselines import export_dataset

    public, heldout = _results(sessions, settings)
    with sessions() as s:
        s.query(PlannerRow).filter_by(name="probe-planner").one().builtin = True
        s.commit()
        dataset = export_dataset(s, current_version())
    assert {r.area for r in dataset.runs} == {public}
    assert heldout not in dataset.model_dump_json()


def test_the_results_command_asks_for_a_generation_with_the_heldout_split_only(
        capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as stopped:
        main(["results", "--heldout-generation", "2", "--server", "http://127.0.0.1:9"])
    assert stopped.value.code != 0
    assert "--heldout-generation goes with --split heldout" in capsys.readouterr().err


def test_uploads_may_not_take_a_heldout_name(client: TestClient, tokens: Tokens) -> None:
    mesh = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"
    answer = client.post("/api/v1/areas", headers=tokens.auth("alice"),
                         data={"name": f"{NAME_PREFIX}0123abcd"},
                         files={"file": ("mesh.obj", mesh, "text/plain")})
    assert answer.status_code == 422 and "reserved" in answer.json()["detail"]
