"""What keeps polling cheap: concurrent reads of one job share one query without serving a read
older than the request (`server.coalesce`), and the leaderboard's gzip representation with an
ETag of its own."""

from __future__ import annotations

import asyncio
import threading
import time

from fastapi.testclient import TestClient
from sqlalchemy.orm import Session, sessionmaker

from server.coalesce import Coalesced
from server.routes.leaderboard import accepts_gzip
from tests.server.conftest import Tokens
from tests.server.test_leaderboard_cache import _add_result

URL = "/api/v1/leaderboard"


def test_concurrent_reads_share_a_query_but_never_an_older_one() -> None:
    calls = 0
    state = {"value": 0}
    lock = threading.Lock()

    def read(key: str) -> tuple[str, int]:
        nonlocal calls
        with lock:
            calls += 1
        seen = state["value"]
        time.sleep(0.05)
        return key, seen

    reads: Coalesced[str, tuple[str, int]] = Coalesced(read)

    async def scenario() -> tuple[list[tuple[str, int]], tuple[str, int], list[tuple[str, int]]]:
        first = await asyncio.gather(*(reads.get("job") for _ in range(40)))
        state["value"] = 1  # changed before the next request: it must see the change
        after = await reads.get("job")
        other = await asyncio.gather(reads.get("a"), reads.get("b"))
        return first, after, list(other)

    first, after, other = asyncio.run(scenario())
    assert first == [("job", 0)] * 40
    assert after == ("job", 1)
    assert other == [("a", 1), ("b", 1)]
    assert calls == 4  # 40 requests, one query; then one each
    assert reads.batches == {}  # nothing kept for keys nobody asks for


def test_a_failed_read_fails_its_waiters_only() -> None:
    attempts = 0

    def read(key: int) -> int:
        nonlocal attempts
        attempts += 1
        if attempts == 1:
            raise RuntimeError("database went away")
        return key

    reads: Coalesced[int, int] = Coalesced(read)

    async def scenario() -> list[object]:
        failed = await asyncio.gather(reads.get(7), return_exceptions=True)
        return [*failed, await reads.get(7)]

    failed, ok = asyncio.run(scenario())
    assert isinstance(failed, RuntimeError) and ok == 7


def test_job_polls_answer_from_the_shared_read(client: TestClient, tokens: Tokens) -> None:
    job = client.post("/api/v1/jobs", headers=tokens.auth("alice"),
                      json={"planner": "classic", "areas": ["maze"], "runs": 2, "seconds": 30})
    assert job.status_code == 201, job.text
    polled = client.get(f"/api/v1/jobs/{job.json()['id']}")
    assert polled.status_code == 200 and polled.json()["status"] == "queued"
    assert polled.headers["Retry-After"] == "2"
    again = client.get(f"/api/v1/jobs/{job.json()['id']}",
                       headers={"If-None-Match": polled.headers["ETag"]})
    assert again.status_code == 304
    assert client.get("/api/v1/jobs/999999").status_code == 404


def test_the_leaderboard_in_gzip_is_a_representation_of_its_own(
        client: TestClient, sessions: sessionmaker[Session]) -> None:
    _add_result(sessions, "gz-a", "maze", 0, 0.5)
    plain = client.get(URL, headers={"Accept-Encoding": "identity"})
    zipped = client.get(URL, headers={"Accept-Encoding": "gzip, deflate"})
    assert "content-encoding" not in plain.headers
    assert zipped.headers["content-encoding"] == "gzip"
    assert zipped.headers["vary"] == "Accept-Encoding" == plain.headers["vary"]
    assert zipped.content == plain.content  # httpx decompressed it
    assert zipped.headers["ETag"] != plain.headers["ETag"]
    assert zipped.headers["ETag"].endswith('-gz"')
    assert int(zipped.headers["content-length"]) < len(plain.content) / 2
    revalidated = client.get(URL, headers={"Accept-Encoding": "gzip",
                                           "If-None-Match": zipped.headers["ETag"]})
    assert revalidated.status_code == 304
    assert revalidated.headers["ETag"] == zipped.headers["ETag"]


def test_accept_encoding_is_read_as_http_says() -> None:
    assert accepts_gzip("gzip")
    assert accepts_gzip("br;q=1.0, gzip;q=0.8, *;q=0.1")
    assert accepts_gzip("*")
    assert not accepts_gzip("gzip;q=0")
    assert not accepts_gzip("identity")
    assert not accepts_gzip(None)
