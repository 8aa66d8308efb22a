"""Fixtures for the website.

- `site`: the app behind a TestClient on a SQLite file holding hand-made results (`stored.py`).
- `service`: a real `flybo serve` (API, pages, one worker) on a temporary data folder, with the
  results of real short jobs on MAZE; and `browser`, Debian's Chromium driven by Playwright.
  Without /usr/bin/chromium the browser tests are skipped, or fail under CI=true.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import pytest
from fastapi.testclient import TestClient

from flybo.app import create_app
from server.db import make_engine, make_session_factory, session_scope
from server.migrate import upgrade
from server.models import User
from server.security import create_token
from server.settings import Settings
from tests.web.stored import HOSTILE, add_area, add_job, add_planner, add_run, current_version

CHROMIUM = Path("/usr/bin/chromium")
ARTIFACTS = Path(__file__).resolve().parents[2] / "test-artifacts" / "web"
FINAL = {"succeeded", "failed", "cancelled"}


@dataclass
class Site:
    client: TestClient
    token: str
    ids: dict[str, int] = field(default_factory=dict)


@pytest.fixture
def site(tmp_path: Path) -> Iterator[Site]:
    """Planners alpha (2 runs), beta (uploaded, hostile description), gamma, and a planner and
    an area whose names are markup, on MAZE; one failed run that no table may count; and a
    legacy run of gamma (made before results named their benchmark version), which only the
    legacy board may count."""
    settings = Settings(data_dir=tmp_path / "data",
                        database_url=f"sqlite:///{tmp_path / 'flybo.sqlite'}")
    engine = make_engine(settings.db_url)
    upgrade(engine)
    sessions = make_session_factory(engine)
    ids: dict[str, int] = {}
    with session_scope(sessions) as s:
        token = create_token(s, "alice", settings.secret_key)
        alice = s.query(User).filter_by(name="alice").one()
        maze = add_area(s, "maze", "MAZE")
        evil_area = add_area(s, "evil-area", HOSTILE)
        alpha = add_planner(s, "alpha", method="original")
        beta = add_planner(s, "beta", builtin=False, description=HOSTILE, owner=alice)
        gamma = add_planner(s, "gamma", method="variant")
        evil = add_planner(s, "<b>evil</b>", description=HOSTILE)
        job = add_job(s, alice, alpha)
        ids["alpha_job"] = job.id
        ids["alpha_run"] = add_run(s, job, maze, 0, coverage=0.8, fscore=0.5,
                                   volume=[0, 1, 2, 3, 4], recall=[0.1, 0.3],
                                   log=f"line one\n{HOSTILE}\n").id
        add_run(s, job, maze, 1, coverage=0.6, fscore=0.7, volume=[0, 2, 4], recall=[0.2])
        add_run(s, job, maze, 2, coverage=0.99, fscore=0.99, volume=[9, 9, 9], recall=[0.9],
                status="failed")
        add_run(s, add_job(s, alice, beta), maze, 0, coverage=0.9, fscore=0.4,
                volume=[0, 5, 6], recall=[0.2])
        add_run(s, add_job(s, alice, gamma), maze, 0, coverage=0.5, fscore=0.3,
                volume=[0, 1, 1], recall=[0.1], time_to_90=30.0)
        ids["legacy_run"] = add_run(s, add_job(s, alice, gamma), maze, 1, coverage=0.95,
                                    fscore=0.95, volume=[0, 8, 9], recall=[0.9],
                                    benchmark_version="legacy").id
        # In another preset, so that it does not change the ranks of the default one.
        ids["evil_run"] = add_run(s, add_job(s, alice, evil, "exact"), evil_area, 0, coverage=0.5,
                                  fscore=0.3, volume=[0, 1], recall=[0.1]).id
    engine.dispose()
    app = create_app(settings, sweeper=False, sync_areas=False,
                     benchmark_version=current_version())
    with TestClient(app) as client:
        yield Site(client, token, ids)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture(scope="session")
def chromium_path() -> str:
    if not CHROMIUM.exists():
        message = f"{CHROMIUM} is missing (apt-get install chromium)"
        if os.environ.get("CI") == "true":
            pytest.fail(message + "; under CI=true it must be there")
        pytest.skip(message + "; set CI=true to make this a failure")
    return str(CHROMIUM)


@pytest.fixture(scope="module")
def browser(chromium_path: str, playwright_driver: Any) -> Iterator[Any]:
    chromium = playwright_driver.chromium.launch(executable_path=chromium_path)
    yield chromium
    chromium.close()


@dataclass
class Service:
    base: str
    token: str
    logs: Path
    jobs: list[dict[str, Any]]
    planners: list[str]

    def auth(self) -> dict[str, str]:
        return {"Authorization": f"Bearer {self.token}"}

    def get(self, path: str) -> Any:
        response = httpx.get(self.base + path, timeout=30)
        response.raise_for_status()
        return response.json()

    def submit(self, planner: str, runs: int, seconds: float,
               preset: str = "default") -> dict[str, Any]:
        response = httpx.post(f"{self.base}/api/v1/jobs", headers=self.auth(), timeout=30,
                              json={"planner": planner, "areas": ["maze"], "runs": runs,
                                    "seconds": seconds, "preset": preset})
        assert response.status_code == 201, response.text
        job: dict[str, Any] = response.json()
        return job

    def wait(self, job_id: int, timeout: float = 180.0) -> dict[str, Any]:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            job: dict[str, Any] = self.get(f"/api/v1/jobs/{job_id}")
            if job["status"] in FINAL:
                return job
            time.sleep(0.5)
        raise AssertionError(f"job {job_id} did not end in {timeout} s: {self.tail()}")

    def tail(self) -> str:
        return self.logs.read_text(errors="replace")[-4000:]


@pytest.fixture(scope="session")
def service(tmp_path_factory: pytest.TempPathFactory, chromium_path: str) -> Iterator[Service]:
    """`flybo serve` with one worker and the results of real jobs on MAZE: Classic with 2 runs
    of 20 s, and a second built-in planner with 1 run when one is registered."""
    tmp = tmp_path_factory.mktemp("service")
    env = {k: v for k, v in os.environ.items() if not k.startswith("FLYBO_")}
    # Heartbeats every 0.5 s: the job page has progress to show within a short run.
    env.update(FLYBO_DATA_DIR=str(tmp / "data"), FLYBO_HEARTBEAT_INTERVAL_S="0.5")
    if "FLYBO_CACHE_DIR" in os.environ:
        env["FLYBO_CACHE_DIR"] = os.environ["FLYBO_CACHE_DIR"]
    token = subprocess.run([sys.executable, "-m", "flybo", "tokens", "create", "--user", "eve"],
                           env=env, capture_output=True, text=True, check=True).stdout.strip()
    port = _free_port()
    logs = tmp / "serve.log"
    with logs.open("wb") as out:
        proc = subprocess.Popen([sys.executable, "-m", "flybo", "serve", "--port", str(port),
                                 "--workers", "1"], env=env, stdout=out,
                                stderr=subprocess.STDOUT)
    service = Service(f"http://127.0.0.1:{port}", token, logs, [], [])
    try:
        deadline = time.monotonic() + 90
        while True:
            try:
                if httpx.get(service.base + "/healthz", timeout=2).status_code == 200:
                    break
            except httpx.HTTPError:
                pass
            assert time.monotonic() < deadline, f"flybo serve did not start: {service.tail()}"
            time.sleep(0.3)
        builtin = [p["id"] for p in service.get("/api/v1/planners") if p["builtin"]]
        # A second planner gives the leaderboard a second row to sort; Rapid when it is there.
        others = sorted((p for p in builtin if not p.startswith("classic-")),
                        key=lambda p: (not p.startswith("rapid-"), p))
        submitted = [service.submit("classic", 2, 20)]
        if others:
            submitted.append(service.submit(others[0], 1, 20))
        for job in submitted:
            done = service.wait(job["id"])
            if job is submitted[0]:
                assert done["status"] == "succeeded", service.tail()
            if done["status"] == "succeeded":  # the second planner's failure is not ours
                service.jobs.append(done)
                service.planners.append(done["planner"])
        yield service
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()


@pytest.fixture
def console_errors() -> list[str]:
    """What the page fixture's tab reported as errors; a test may take out the ones it caused
    on purpose."""
    return []


@pytest.fixture
def page(browser: Any, console_errors: list[str]) -> Iterator[Any]:
    """A fresh browser tab; the test fails on any console error or uncaught exception (a
    Content-Security-Policy violation is reported as a console error)."""
    context = browser.new_context(viewport={"width": 1280, "height": 900})
    tab = context.new_page()
    tab.on("console", lambda m: console_errors.append(m.text) if m.type == "error" else None)
    tab.on("pageerror", lambda e: console_errors.append(str(e)))
    yield tab
    context.close()
    assert not console_errors, console_errors
