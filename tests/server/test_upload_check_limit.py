"""At most `Settings.max_concurrent_checks` uploads are checked at once by one API process: the
next one is answered 429 with a Retry-After header and stores nothing; a freed slot takes uploads
again.

The uploads are real concurrent requests against the real app; the dry run is one that waits for
the test to let it finish, so that the uploads are known to be in their check together.
"""

from __future__ import annotations

import io
import threading
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import httpx
import pytest
from fastapi.testclient import TestClient
from sqlalchemy import func, select
from sqlalchemy.orm import Session, sessionmaker

from server.app import create_app as create_api
from server.models import PlannerRow
from server.planner_package import (
    CHECKS_RETRY_AFTER_S,
    CheckOutcome,
    PlannerPackage,
)
from server.settings import Settings

# The default of `Settings.max_concurrent_checks`.
MAX_CONCURRENT_CHECKS = Settings.model_fields["max_concurrent_checks"].default

GOOD = b'''
import numpy as np
from planners.api import Plan, Planner


class Hover(Planner):
    def plan(self, obs):
        return Plan(np.array([[*obs.pose.position, obs.pose.yaw]]))
'''


class HeldCheck:
    """A dry run that passes once `release` is set, counting the checks running at once."""

    def __init__(self) -> None:
        self.release = threading.Event()
        self.lock = threading.Lock()
        self.running = 0
        self.most = 0
        self.entered = threading.Semaphore(0)

    def __call__(self, package: PlannerPackage) -> CheckOutcome:
        with self.lock:
            self.running += 1
            self.most = max(self.most, self.running)
        self.entered.release()
        try:
            if not self.release.wait(timeout=60):
                return CheckOutcome(False, "never released", 60.0)
            return CheckOutcome(True, "dry run passed", 0.1)
        finally:
            with self.lock:
                self.running -= 1


def _upload(client: TestClient, token: str, name: str) -> httpx.Response:
    return client.post("/api/v1/planners", headers={"Authorization": f"Bearer {token}"},
                       files={"file": ("planner.py", io.BytesIO(GOOD))}, data={"name": name})


def _stored(sessions: sessionmaker[Session]) -> int:
    with sessions() as s:
        return s.scalar(select(func.count(PlannerRow.id)).where(
            PlannerRow.builtin.is_(False))) or 0


@pytest.fixture
def held() -> Iterator[HeldCheck]:
    check = HeldCheck()
    yield check
    check.release.set()  # a failing test must not leave request threads waiting


def test_uploads_past_the_limit_get_429_and_store_nothing(
        settings: Settings, sessions: sessionmaker[Session], tokens: Any,
        held: HeldCheck) -> None:
    app = create_api(settings, sweeper=False, sync_areas=False, planner_check=held)
    with TestClient(app) as client, ThreadPoolExecutor(MAX_CONCURRENT_CHECKS) as pool:
        first = [pool.submit(_upload, client, tokens.alice, f"held-{i}")
                 for i in range(MAX_CONCURRENT_CHECKS)]
        for _ in first:  # every slot is taken by a check in progress
            assert held.entered.acquire(timeout=30)
        refused = _upload(client, tokens.bob, "one-too-many")
        assert refused.status_code == 429, refused.text
        assert refused.headers["Retry-After"] == str(CHECKS_RETRY_AFTER_S)
        detail = refused.json()["detail"]
        assert "being checked" in detail and "nothing was stored" in detail
        assert _stored(sessions) == 0
        held.release.set()
        assert [future.result(timeout=60).status_code for future in first] == [201] * len(first)
        assert held.most == MAX_CONCURRENT_CHECKS
        # The slots are free again: the refused upload now goes through.
        again = _upload(client, tokens.bob, "one-too-many")
        assert again.status_code == 201, again.text
    assert _stored(sessions) == MAX_CONCURRENT_CHECKS + 1


def test_a_refused_check_frees_its_slot(settings: Settings, sessions: sessionmaker[Session],
                                        tokens: Any) -> None:
    # Refusals (422) and failures of the check leave as many slots as before.
    app = create_api(settings, sweeper=False, sync_areas=False,
                     planner_check=lambda package: CheckOutcome(False, "crashed", 0.1))
    with TestClient(app) as client:
        for i in range(MAX_CONCURRENT_CHECKS + 2):
            response = _upload(client, tokens.alice, f"bad-{i}")
            assert response.status_code == 422 and "crashed" in response.json()["detail"]
        static = client.post("/api/v1/planners",
                             headers={"Authorization": f"Bearer {tokens.alice}"},
                             files={"file": ("planner.py", io.BytesIO(b"x = 1\n"))},
                             data={"name": "static"})
        assert static.status_code == 422
    app = create_api(settings, sweeper=False, sync_areas=False,
                     planner_check=lambda package: CheckOutcome(True, "passed", 0.1))
    with TestClient(app) as client, ThreadPoolExecutor(MAX_CONCURRENT_CHECKS) as pool:
        answers = list(pool.map(lambda i: _upload(client, tokens.alice, f"good-{i}"),
                                range(MAX_CONCURRENT_CHECKS)))
    assert [a.status_code for a in answers] == [201] * MAX_CONCURRENT_CHECKS
    assert _stored(sessions) == MAX_CONCURRENT_CHECKS
