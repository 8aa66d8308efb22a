"""The leaderboard endpoint's cache: the same bytes FastAPI would serialize, ETag/304, exact
invalidation when a result lands, and the security headers on cached answers (SQLite and
PostgreSQL); and one benchmark version per board, never two ranked together."""

from __future__ import annotations

import asyncio
import threading

import pytest
from fastapi import FastAPI
from fastapi.testclient import TestClient
from httpx import Headers
from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from server.app import create_app as create_api
from server.leaderboard import _Gate, build_leaderboard, compute_leaderboard
from server.middleware import SECURITY_HEADERS
from server.models import LEGACY_VERSION, AreaRow, Job, PlannerRow, Run, RunResult, RunState, User
from server.schemas import Leaderboard
from server.settings import Settings
from tests.web.stored import current_version

URL = "/api/v1/leaderboard"


def _add_result(sessions: sessionmaker[Session], planner: str, area: str, seed: int,
                coverage: float, *, preset: str = "default",
                status: str = RunState.SUCCEEDED.value,
                benchmark_version: str | None = None, observable: float | None = None,
                time_to_90: float | None = None) -> None:
    """One finished run with its result, creating the owner, planner and area when missing;
    made by `benchmark_version` (this tree's by default). Its explored observable volume is
    `observable`, 1000 m³ times the coverage by default, as its volume at the plateau; a
    'legacy' result has no metrics block."""
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
            metrics=None if benchmark_version == LEGACY_VERSION else {
                "coverage": coverage, "fscore": coverage * 0.9, "rmse_m": 0.02,
                "explored_observable_m3": volume if observable is None else observable,
                "time_to_90_coverage_s": time_to_90}))


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
    def board(preset: str = "default", area: str | None = None,
              benchmark_version: str | None = None) -> Leaderboard:
        with sessions() as s:
            return compute_leaderboard(s, preset, area,
                                       benchmark_version=benchmark_version or current_version())

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
        expected = compute_leaderboard(s, params.get("preset", "default"), params.get("area"),
                                       benchmark_version=current_version())
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
        version = current_version()
        board = build_leaderboard(s, "default", benchmark_version=version)
        assert board == compute_leaderboard(s, "default", benchmark_version=version)
        board.entries.clear()  # a copy: changing it does not reach the cache
        assert build_leaderboard(s, "default", benchmark_version=version) == \
            compute_leaderboard(s, "default", benchmark_version=version)


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


def test_versions_are_never_ranked_together(client: TestClient,
                                            results: sessionmaker[Session]) -> None:
    """Results of two benchmark versions: each board holds its own only, the default is the
    current version's, and each version's board is cached under its own key."""
    current = current_version()
    _add_result(results, "lb-old", "maze", 0, 0.99, benchmark_version="2020.01-1")
    _add_result(results, "lb-a", "maze", 5, 0.1, benchmark_version="2020.01-1")
    default = client.get(URL)
    assert default.status_code == 200
    board = default.json()
    assert board["benchmark_version"] == current
    assert "lb-old-v1" not in {p["planner"] for p in board["overall"]}
    entry = next(e for e in board["entries"] if (e["planner"], e["area"]) == ("lb-a-v1", "maze"))
    assert entry["runs"] == 2 and entry["coverage"]["min"] == pytest.approx(0.5)
    same = client.get(URL, params={"benchmark_version": current})
    assert same.content == default.content and same.headers["etag"] == default.headers["etag"]

    old = client.get(URL, params={"benchmark_version": "2020.01-1"})
    assert old.status_code == 200 and old.headers["etag"] != default.headers["etag"]
    body = old.json()
    assert body["benchmark_version"] == "2020.01-1" and body["areas"] == ["maze"]
    assert [(p["planner"], p["rank"]) for p in body["overall"]] == [("lb-old-v1", 1),
                                                                    ("lb-a-v1", 2)]
    assert all(e["runs"] == 1 for e in body["entries"])
    assert old.content == _reference_body(results, {"benchmark_version": "2020.01-1"})
    # Cached per version: asking again for each gives each its own bytes.
    assert client.get(URL).content == default.content
    assert client.get(URL, params={"benchmark_version": "2020.01-1"}).content == old.content

    listed = client.get("/api/v1/benchmark-versions").json()
    assert listed["current"] == current and listed["preset"] is None
    assert [(v["benchmark_version"], v["runs"], v["current"]) for v in listed["versions"]] == [
        ("2020.01-1", 2, False), (current, 12, True)]
    exact = client.get("/api/v1/benchmark-versions", params={"preset": "exact"}).json()
    assert exact["versions"] == []


def test_an_unknown_version_is_a_404_naming_the_known_ones(
        client: TestClient, results: sessionmaker[Session]) -> None:
    _add_result(results, "lb-old", "maze", 0, 0.9, benchmark_version=LEGACY_VERSION)
    for url, params in ((URL, {}), ("/api/v1/curves", {"area": "maze"})):
        answer = client.get(url, params={**params, "benchmark_version": "1999.01-1"})
        assert answer.status_code == 404, url
        detail = answer.json()["detail"]
        assert "1999.01-1" in detail and current_version() in detail and "legacy" in detail
    # A known version without results in this preset (or area) is an empty board.
    empty = client.get(URL, params={"benchmark_version": LEGACY_VERSION, "preset": "exact"})
    assert empty.status_code == 200 and empty.json()["overall"] == []
    assert client.get(URL, params={"benchmark_version": "x" * 65}).status_code == 422


def test_relative_coverage_compares_the_explored_observable_volume(
        client: TestClient, sessions: sessionmaker[Session]) -> None:
    """From the metrics block when there is one; a legacy result's volume at the plateau."""
    _add_result(sessions, "lb-a", "maze", 0, 0.5, observable=300.0, time_to_90=40.0)
    _add_result(sessions, "lb-a", "maze", 1, 0.5, observable=300.0, time_to_90=None)
    _add_result(sessions, "lb-b", "maze", 0, 0.6, observable=600.0, time_to_90=80.0)
    board = client.get(URL).json()
    relative = {p["planner"]: p["mean_relative_coverage"] for p in board["overall"]}
    assert relative == {"lb-a-v1": pytest.approx(0.5), "lb-b-v1": pytest.approx(1.0)}
    # The leaderboard metrics of the measures, time to 90 % among them (undefined runs left out).
    keys = [m["key"] for m in board["metrics"]]
    assert "time_to_90_coverage_s" in keys and "coverage" in keys
    assert "explored_observable_m3" not in keys  # not a leaderboard metric
    a = next(e for e in board["entries"] if e["planner"] == "lb-a-v1")
    assert a["metrics"]["time_to_90_coverage_s"] == {"mean": 40.0, "min": 40.0, "max": 40.0,
                                                     "ci_low": 40.0, "ci_high": 40.0}
    assert a["metrics"]["coverage"]["mean"] == pytest.approx(0.5)
    means = {p["planner"]: p["mean_metrics"]["time_to_90_coverage_s"] for p in board["overall"]}
    assert means == {"lb-a-v1": 40.0, "lb-b-v1": 80.0}

    _add_result(sessions, "lb-a", "maze", 0, 0.5, benchmark_version=LEGACY_VERSION)
    _add_result(sessions, "lb-b", "maze", 0, 0.8, benchmark_version=LEGACY_VERSION)
    legacy = client.get(URL, params={"benchmark_version": LEGACY_VERSION}).json()
    relative = {p["planner"]: p["mean_relative_coverage"] for p in legacy["overall"]}
    assert relative == {"lb-a-v1": pytest.approx(500 / 800), "lb-b-v1": pytest.approx(1.0)}
    a = next(e for e in legacy["entries"] if e["planner"] == "lb-a-v1")
    assert a["metrics"]["coverage"]["mean"] == pytest.approx(0.5)  # from the column
    assert a["metrics"]["time_to_90_coverage_s"]["mean"] is None  # never recorded


def test_an_api_without_a_current_version_takes_the_newest_results(
        settings: Settings, sessions: sessionmaker[Session]) -> None:
    _add_result(sessions, "lb-a", "maze", 0, 0.5, benchmark_version=LEGACY_VERSION)
    _add_result(sessions, "lb-b", "maze", 0, 0.6, benchmark_version="2030.01-1")
    with TestClient(create_api(settings, sweeper=False, sync_areas=False)) as plain:
        board = plain.get(URL).json()
        assert board["benchmark_version"] == "2030.01-1"
        assert [p["planner"] for p in board["overall"]] == ["lb-b-v1"]
        assert plain.get("/api/v1/benchmark-versions").json()["current"] == "2030.01-1"
