"""The leaderboard endpoint's cache: the same bytes FastAPI would serialize, ETag/304, exact
invalidation when a result lands, and the security headers on cached answers (SQLite and
PostgreSQL)."""

from __future__ import annotations

import asyncio
import threading

import pytest
from fastapi import FastAPI
from fastapi.testclient import TestClient
from httpx import Headers
from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from server.leaderboard import _Gate, build_leaderboard, compute_leaderboard
from server.middleware import SECURITY_HEADERS
from server.models import AreaRow, Job, PlannerRow, Run, RunResult, RunState, User
from server.schemas import Leaderboard
from tests.web.stored import current_version

URL = "/api/v1/leaderboard"


def _add_result(sessions: sessionmaker[Session], planner: str, area: str, seed: int,
                coverage: float, *, preset: str = "default",
                status: str = RunState.SUCCEEDED.value,
                benchmark_version: str | None = None) -> None:
    """One finished run with its result, creating the owner, planner and area when missing;
    made by `benchmark_version` (this tree's by default)."""
    benchmark_version = benchmark_version or current_version()
    with sessions() as s, s.begin():
        owner = s.scalar(select(User).where(User.name == "lb-owner"))
        if owner is None:
            owner = User(name="lb-owner")
            s.add(owner)
            s.flush()
        row = s.scalar(select(PlannerRow).where(PlannerRow.name == planner))
        if row is None:
            row = PlannerRow(name=planner, version=1, builtin=False, owner_id=owner.id,
                             description="test")
            s.add(row)
        place = s.scalar(select(AreaRow).where(AreaRow.name == area))
        if place is None:
            place = AreaRow(name=area, builtin=True, content_hash="test", plateau_s=100.0,
                            voxel_size=0.1, stats={})
            s.add(place)
        s.flush()
        job = Job(user_id=owner.id, planner_id=row.id, preset=preset, seconds=None,
                  runs_per_area=1, request_hash="test")
        s.add(job)
        s.flush()
        run = Run(job_id=job.id, area_id=place.id, seed=seed, preset=preset, seconds=100.0,
                  status=status, progress=1.0, sim_time_s=100.0, attempts=1)
        s.add(run)
        s.flush()
        volume = 1000.0 * coverage
        s.add(RunResult(
            run_id=run.id, outcome="succeeded", reason="time limit reached",
            simulated_until_s=100.0, explored_volume_m3=volume, volume_at_plateau_m3=volume,
            observable_volume_m3=1000.0, coverage=coverage, volumetric_efficiency=volume / 100,
            precision=coverage, recall=coverage, fscore=coverage * 0.9, rmse_m=0.02,
            collisions=0, path_length_m=100.0 + seed, iterations=50 + seed,
            planning_ms_median=3.0, planning_ms_mean=3.5, planning_ms_max=9.0,
            wall_seconds=10.0, benchmark_version=benchmark_version,
            metrics={"coverage": coverage, "explored_observable_m3": volume,
                     "time_to_90_coverage_s": None}))


@pytest.fixture
def results(sessions: sessionmaker[Session]) -> sessionmaker[Session]:
    for p, planner in enumerate(("lb-a", "lb-b", "lb-c")):
        for a, area in enumerate(("maze", "warehouse")):
            for seed in range(2):
                _add_result(sessions, planner, area, seed, 0.5 + 0.1 * p + 0.01 * a + 0.003 * seed)
    return sessions


def _reference_body(sessions: sessionmaker[Session], params: dict[str, str]) -> bytes:
    """What a plain FastAPI route with `response_model=Leaderboard` answers for the board."""
    app = FastAPI()

    @app.get("/board", response_model=Leaderboard)
    def board(preset: str = "default", area: str | None = None) -> Leaderboard:
        with sessions() as s:
            return compute_leaderboard(s, preset, area)

    with TestClient(app) as plain:
        return plain.get("/board", params=params).content


def _has_security_headers(headers: Headers) -> bool:
    return all(headers.get(k) == v for k, v in SECURITY_HEADERS.items())


@pytest.mark.parametrize("params", [{}, {"area": "warehouse"}, {"preset": "exact"}])
def test_body_is_the_serialized_response_model(
    client: TestClient, results: sessionmaker[Session], params: dict[str, str],
) -> None:
    for _ in range(2):  # computed, then from the cache
        answer = client.get(URL, params=params)
        assert answer.status_code == 200
        assert answer.headers["content-type"] == "application/json"
        assert answer.content == _reference_body(results, params)
    with results() as s:
        expected = compute_leaderboard(s, params.get("preset", "default"), params.get("area"))
    assert answer.json() == expected.model_dump(mode="json")


def test_etag_gives_304_while_unchanged(client: TestClient, results: sessionmaker[Session]) -> None:
    first = client.get(URL)
    etag = first.headers["etag"]
    assert etag.startswith('"') and etag.endswith('"') and len(etag) > 8
    assert first.headers["cache-control"] == "no-cache"
    assert _has_security_headers(first.headers)
    for sent in (etag, f"W/{etag}", f'"other", {etag}', "*"):
        again = client.get(URL, headers={"If-None-Match": sent})
        assert again.status_code == 304, sent
        assert again.content == b""
        assert again.headers["etag"] == etag
        assert _has_security_headers(again.headers)
    other = client.get(URL, headers={"If-None-Match": '"not-it"'})
    assert other.status_code == 200 and other.content == first.content
    # Each filter has its own body and tag.
    area = client.get(URL, params={"area": "maze"})
    assert area.headers["etag"] != etag
    assert client.get(URL, params={"area": "maze"},
                      headers={"If-None-Match": etag}).status_code == 200


def test_a_landing_result_changes_the_answer_at_once(
    client: TestClient, results: sessionmaker[Session],
) -> None:
    before = client.get(URL)
    area_before = client.get(URL, params={"area": "maze"})
    _add_result(results, "lb-a", "maze", 7, 0.99)
    after = client.get(URL, headers={"If-None-Match": before.headers["etag"]})
    assert after.status_code == 200 and after.headers["etag"] != before.headers["etag"]
    assert _has_security_headers(after.headers)
    entry = next(e for e in after.json()["entries"]
                 if (e["planner"], e["area"]) == ("lb-a-v1", "maze"))
    assert entry["runs"] == 3 and entry["coverage"]["max"] == pytest.approx(0.99)
    assert after.content == _reference_body(results, {})
    area_after = client.get(URL, params={"area": "maze"})
    assert area_after.content != area_before.content
    assert area_after.content == _reference_body(results, {"area": "maze"})
    # A run that did not succeed, or of another preset, leaves the tag as it is.
    _add_result(results, "lb-b", "maze", 8, 0.2, status=RunState.FAILED.value)
    _add_result(results, "lb-b", "maze", 9, 0.2, preset="exact")
    same = client.get(URL, headers={"If-None-Match": after.headers["etag"]})
    assert same.status_code == 304


def test_a_new_planner_changes_the_answer(client: TestClient,
                                          results: sessionmaker[Session]) -> None:
    before = client.get(URL).json()
    _add_result(results, "lb-new", "warehouse", 0, 0.95)
    after = client.get(URL).json()
    assert {p["planner"] for p in after["overall"]} - {p["planner"] for p in before["overall"]} \
        == {"lb-new-v1"}


def test_the_pages_read_the_same_board(client: TestClient, results: sessionmaker[Session]) -> None:
    client.get(URL)
    with results() as s:
        board = build_leaderboard(s, "default")
        assert board == compute_leaderboard(s, "default")
        board.entries.clear()  # a copy: changing it does not reach the cache
        assert build_leaderboard(s, "default") == compute_leaderboard(s, "default")


def test_concurrent_requests_agree(client: TestClient, results: sessionmaker[Session]) -> None:
    expected = client.get(URL).content
    bodies: list[bytes] = []

    def fetch() -> None:
        for _ in range(5):
            bodies.append(client.get(URL).content)

    threads = [threading.Thread(target=fetch) for _ in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(bodies) == 30 and set(bodies) == {expected}


def test_gate_answers_each_request_with_a_check_started_after_it() -> None:
    """Requests arriving during a check wait for the next one; one check answers them all."""

    async def scenario() -> tuple[list[tuple[int, int, int]], list[int]]:
        gate = _Gate()
        started: list[int] = []
        release = [threading.Event(), threading.Event()]

        def check() -> tuple[int, int, int]:
            n = len(started)
            started.append(n)
            release[n].wait(5)
            return (n, 0, 0)

        first = asyncio.create_task(gate.version(check))
        while not started:
            await asyncio.sleep(0.001)
        later = [asyncio.create_task(gate.version(check)) for _ in range(5)]
        await asyncio.sleep(0.01)
        release[0].set()
        release[1].set()
        versions = [await first] + [await t for t in later]
        return versions, started

    versions, started = asyncio.run(scenario())
    assert started == [0, 1]  # two checks for six requests
    assert versions == [(0, 0, 0)] + [(1, 0, 0)] * 5


def test_gate_passes_errors_on_and_recovers() -> None:
    async def scenario() -> tuple[str, tuple[int, int, int]]:
        gate = _Gate()

        def broken() -> tuple[int, int, int]:
            raise RuntimeError("database gone")

        try:
            await gate.version(broken)
            failed = ""
        except RuntimeError as exc:
            failed = str(exc)
        return failed, await gate.version(lambda: (1, 2, 3))

    assert asyncio.run(scenario()) == ("database gone", (1, 2, 3))
