"""What API processes share through Redis (`server.shared_state`): one token bucket per client
for all of them, and the results epoch that tells each process's leaderboard cache it is stale.
Against the real Redis server (fails under CI=true when it does not answer); the in-process
buckets of the embedded default beside them."""

from __future__ import annotations

import asyncio
from collections.abc import Iterator

import pytest
import redis
from fastapi.testclient import TestClient
from sqlalchemy.orm import Session, sessionmaker

from server.app import create_app as create_api
from server.settings import Settings
from server.shared_state import (
    EPOCH_KEY,
    EpochNet,
    LocalLimiter,
    RedisLimiter,
    bump_results_epoch,
    read_results_epoch,
)
from tests.server.test_leaderboard_cache import _add_result
from tests.web.stored import current_version

URL = "/api/v1/leaderboard"


async def _waits(limiter: LocalLimiter | RedisLimiter, key: str, n: int) -> list[float]:
    return [await limiter.wait(key) for _ in range(n)]


@pytest.mark.parametrize("kind", ["local", "redis"])
def test_a_bucket_allows_its_burst_then_tells_the_wait(kind: str,
                                                       request: pytest.FixtureRequest) -> None:
    limiter: LocalLimiter | RedisLimiter
    if kind == "local":
        limiter = LocalLimiter(rate_per_minute=6.0, burst=3)
    else:
        limiter = RedisLimiter(request.getfixturevalue("redis_url"), "t1", 6.0, 3)
    waits = asyncio.run(_waits(limiter, "client", 5))
    assert waits[:3] == [0.0, 0.0, 0.0]
    # One token every 10 s at 6 a minute: the next comes in 10 s less what has refilled.
    assert 9.0 < waits[3] <= 10.0 and 9.0 < waits[4] <= 10.0
    # Looking does not take a token, and another client has its own bucket.
    assert asyncio.run(limiter.wait("client", consume=False)) > 9.0
    assert asyncio.run(limiter.wait("other")) == 0.0


def test_two_limiters_on_one_redis_enforce_one_limit(redis_url: str) -> None:
    """Two API processes hold a limiter each: together they let the burst through once."""
    first = RedisLimiter(redis_url, "writes", 60.0, 4)
    second = RedisLimiter(redis_url, "writes", 60.0, 4)

    async def alternate() -> list[float]:
        return [await (first if i % 2 else second).wait("t:abc") for i in range(8)]

    waits = asyncio.run(alternate())
    assert waits[:4] == [0.0] * 4
    assert all(w > 0.5 for w in waits[4:])


def test_an_unreachable_redis_lets_requests_through() -> None:
    limiter = RedisLimiter("redis://127.0.0.1:1/0", "writes", 1.0, 1)
    assert asyncio.run(_waits(limiter, "k", 3)) == [0.0, 0.0, 0.0]
    assert read_results_epoch("redis://127.0.0.1:1/0") is None


def test_the_epoch_starts_anywhere_and_only_grows(redis_url: str) -> None:
    client = redis.Redis.from_url(redis_url)
    client.delete(EPOCH_KEY)
    first = read_results_epoch(redis_url)
    assert first is not None and first >= 1
    bump_results_epoch(redis_url)
    assert read_results_epoch(redis_url) == first + 1
    net = EpochNet(redis_url)
    assert not net.check((1, 5, 7))  # the first look only remembers
    assert not net.check((1, 5, 7))
    assert net.check((2, 9, 7))  # a result landed that nobody announced
    assert read_results_epoch(redis_url) == first + 2


@pytest.fixture
def shared_client(settings: Settings, sessions: sessionmaker[Session],
                  redis_url: str) -> Iterator[TestClient]:
    shared = settings.model_copy(update={"redis_url": redis_url})
    app = create_api(shared, sweeper=False, sync_areas=False,
                     benchmark_version=current_version())
    with TestClient(app) as client:
        yield client


def test_the_leaderboard_follows_the_shared_epoch(shared_client: TestClient,
                                                  sessions: sessionmaker[Session],
                                                  redis_url: str) -> None:
    """With Redis the board's version is the epoch: a worker's bump after it stored a result
    makes every API process recompute; the database aggregate is not asked."""
    _add_result(sessions, "ep-a", "maze", 0, 0.5)
    first = shared_client.get(URL)
    assert first.status_code == 200
    assert [e["planner"] for e in first.json()["entries"]] == ["ep-a-v1"]
    _add_result(sessions, "ep-b", "maze", 0, 0.7)
    bump_results_epoch(redis_url)
    second = shared_client.get(URL, headers={"If-None-Match": first.headers["ETag"]})
    assert second.status_code == 200
    assert {e["planner"] for e in second.json()["entries"]} == {"ep-a-v1", "ep-b-v1"}
    again = shared_client.get(URL, headers={"If-None-Match": second.headers["ETag"]})
    assert again.status_code == 304


def test_without_redis_the_board_checks_the_database(client: TestClient,
                                                     sessions: sessionmaker[Session]) -> None:
    assert client.app.state.results_epoch is None  # type: ignore[attr-defined]
    _add_result(sessions, "db-a", "maze", 0, 0.5)
    assert len(client.get(URL).json()["entries"]) == 1
    _add_result(sessions, "db-b", "maze", 0, 0.6)
    assert len(client.get(URL).json()["entries"]) == 2
