"""The service fixtures of tests/server, on SQLite only: these tests are about HTTP behaviour."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from sqlalchemy.orm import Session, sessionmaker

from server.app import create_app
from server.db import make_engine, make_session_factory, session_scope
from server.migrate import upgrade
from server.security import create_token
from server.settings import Settings


@pytest.fixture
def settings(tmp_path: Path) -> Settings:
    return Settings(data_dir=tmp_path / "data")


@pytest.fixture
def sessions(settings: Settings) -> Iterator[sessionmaker[Session]]:
    engine = make_engine(settings.db_url)
    upgrade(engine)
    yield make_session_factory(engine)
    engine.dispose()


@pytest.fixture
def token(sessions: sessionmaker[Session], settings: Settings) -> str:
    with session_scope(sessions) as session:
        return create_token(session, "mallory", settings.secret_key)


@pytest.fixture
def client(settings: Settings, sessions: sessionmaker[Session]) -> Iterator[TestClient]:
    with TestClient(create_app(settings, sweeper=False, sync_areas=False)) as test_client:
        yield test_client
