"""Fixtures for the service: real databases (SQLite, and PostgreSQL when it answers), a real
filesystem broker, the app behind a TestClient, and tokens for three users.

PostgreSQL and Redis tests run whenever the servers answer; with CI=true an unreachable server
fails the test instead of skipping it.
"""

from __future__ import annotations

import os
import uuid
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import create_engine, text
from sqlalchemy.orm import Session, sessionmaker

from flybo.app import create_app
from server.db import make_engine, make_session_factory, session_scope
from server.migrate import upgrade
from server.security import create_token
from server.settings import Settings
from tests.web.stored import current_version

POSTGRES_ADMIN_URL = os.environ.get("FLYBO_TEST_POSTGRES_URL",
                                    "postgresql+psycopg://postgres@127.0.0.1:5432/test")


def _worker_redis_url(base: str) -> str:
    """`base` with its database index lowered by the xdist worker's number (gw0: 15, gw1: 14,
    ...): `redis_url` empties its database, and that must not wipe the queued jobs of a test
    another worker is running at the same time."""
    worker = os.environ.get("PYTEST_XDIST_WORKER", "gw0").removeprefix("gw")
    url, _, db = base.rpartition("/")
    if not (worker.isdigit() and db.isdigit()) or int(db) < int(worker):
        return base
    return f"{url}/{int(db) - int(worker)}"


REDIS_URL = _worker_redis_url(os.environ.get("FLYBO_TEST_REDIS_URL", "redis://127.0.0.1:6379/15"))


def unavailable(what: str, why: str) -> None:
    """Skip, or fail under CI where every service must be there."""
    message = f"{what} is not reachable ({why})"
    if os.environ.get("CI") == "true":
        pytest.fail(message + "; under CI=true it must be")
    pytest.skip(message + "; set CI=true to make this a failure")


def _postgres_reason() -> str | None:
    try:
        engine = create_engine(POSTGRES_ADMIN_URL, isolation_level="AUTOCOMMIT")
        with engine.connect() as conn:
            conn.execute(text("SELECT 1"))
        engine.dispose()
    except Exception as exc:
        return str(exc).splitlines()[0]
    return None


def redis_reason() -> str | None:
    import redis

    try:
        redis.Redis.from_url(REDIS_URL, socket_connect_timeout=2).ping()
    except Exception as exc:
        return str(exc).splitlines()[0]
    return None


@pytest.fixture(scope="session", autouse=True)
def record_builder() -> Iterator[None]:
    """Runs flown in this process get their reproducibility record, as `flybo worker` gives
    them (it installs the builder: `worker` may not import `flybo`)."""
    from flybo.record import reproducibility_record
    from worker.runner import install_record_builder

    install_record_builder(reproducibility_record)
    yield
    install_record_builder(None)


@pytest.fixture(scope="session")
def postgres_url() -> Iterator[str]:
    """A fresh PostgreSQL database for this test session, dropped at the end."""
    reason = _postgres_reason()
    if reason is not None:
        unavailable("PostgreSQL", reason)
    name = f"flybo_test_{uuid.uuid4().hex[:10]}"
    admin = create_engine(POSTGRES_ADMIN_URL, isolation_level="AUTOCOMMIT")
    with admin.connect() as conn:
        conn.execute(text(f'CREATE DATABASE "{name}"'))
    url = admin.url.set(database=name).render_as_string(hide_password=False)
    yield url
    with admin.connect() as conn:
        conn.execute(text(
            f"SELECT pg_terminate_backend(pid) FROM pg_stat_activity WHERE datname = '{name}'"))
        conn.execute(text(f'DROP DATABASE IF EXISTS "{name}"'))
    admin.dispose()


def fresh_postgres_schema(url: str) -> None:
    """An empty schema in the session's database. What a previous test left connected (an app's
    area-sync process still writing rows, say) is disconnected first: its inserts and the drop
    would otherwise deadlock."""
    engine = create_engine(url, isolation_level="AUTOCOMMIT")
    with engine.connect() as conn:
        conn.execute(text("SELECT pg_terminate_backend(pid) FROM pg_stat_activity "
                          "WHERE datname = current_database() AND pid <> pg_backend_pid()"))
        conn.execute(text("DROP SCHEMA public CASCADE"))
        conn.execute(text("CREATE SCHEMA public"))
    engine.dispose()


@pytest.fixture(params=["sqlite", "postgresql"])
def database_url(request: pytest.FixtureRequest, tmp_path: Path) -> str:
    """An empty database of each kind."""
    if request.param == "sqlite":
        return f"sqlite:///{tmp_path / 'flybo.sqlite'}"
    url: str = request.getfixturevalue("postgres_url")
    fresh_postgres_schema(url)
    return url


@pytest.fixture
def settings(database_url: str, tmp_path: Path) -> Settings:
    return Settings(data_dir=tmp_path / "data", database_url=database_url,
                    heartbeat_interval_s=0.5, heartbeat_timeout_s=5.0)


@pytest.fixture
def sessions(settings: Settings) -> Iterator[sessionmaker[Session]]:
    engine = make_engine(settings.db_url)
    upgrade(engine)
    yield make_session_factory(engine)
    engine.dispose()


@dataclass
class Tokens:
    alice: str
    bob: str
    admin: str

    def auth(self, who: str) -> dict[str, str]:
        return {"Authorization": f"Bearer {getattr(self, who)}"}


@pytest.fixture
def tokens(sessions: sessionmaker[Session], settings: Settings) -> Tokens:
    with session_scope(sessions) as session:
        return Tokens(alice=create_token(session, "alice", settings.secret_key),
                      bob=create_token(session, "bob", settings.secret_key),
                      admin=create_token(session, "root", settings.secret_key, admin=True))


@pytest.fixture
def client(settings: Settings, sessions: sessionmaker[Session]) -> Iterator[TestClient]:
    # The version the hand-made results of the tests are stored under (`tests.web.stored`).
    app = create_app(settings, sweeper=False, sync_areas=False,
                     benchmark_version=current_version())
    with TestClient(app) as test_client:
        yield test_client


@pytest.fixture
def redis_url() -> str:
    """An emptied Redis database (index 15 by default, one per xdist worker) for broker
    tests."""
    reason = redis_reason()
    if reason is not None:
        unavailable("Redis", reason)
    import redis

    redis.Redis.from_url(REDIS_URL).flushdb()
    return REDIS_URL


@pytest.fixture
def fresh_postgres_url(postgres_url: str) -> str:
    """The session's PostgreSQL database, emptied."""
    fresh_postgres_schema(postgres_url)
    return postgres_url
