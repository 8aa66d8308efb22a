"""The built-in areas' rows are written by a process of their own (`server.area_sync`): the API
process builds no area, and a failure is logged, not raised into the API."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest
from sqlalchemy import func, select

from server import area_sync, catalog
from server.db import make_engine, make_session_factory
from server.migrate import upgrade
from server.models import AreaRow

pytestmark = pytest.mark.slow  # builds (or loads) the eleven areas


def test_the_rows_are_written_from_another_process(tmp_path: Path,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    url = f"sqlite:///{tmp_path / 'flybo.sqlite'}"
    engine = make_engine(url)
    upgrade(engine)
    sessions = make_session_factory(engine)

    def not_here(*_: object) -> None:
        raise AssertionError("the API process built the areas")

    monkeypatch.setattr(catalog, "sync_builtin_areas", not_here)
    monkeypatch.setattr(area_sync, "sync_builtin_areas", not_here)
    area_sync.sync_areas(url, sessions)
    from areas.registry import area_names

    with sessions() as session:
        names = set(session.scalars(select(AreaRow.name)))
    assert names == set(area_names())
    engine.dispose()


def test_one_process_per_host_syncs_a_database(tmp_path: Path) -> None:
    """While one process holds the host's lock for a database, another API process's sync
    leaves the rows to it (the test above shows a sync that holds it writing them)."""
    url = f"sqlite:///{tmp_path / 'flybo.sqlite'}"
    engine = make_engine(url)
    upgrade(engine)
    sessions = make_session_factory(engine)

    def count() -> int:
        with sessions() as session:
            return int(session.scalar(select(func.count(AreaRow.id))) or 0)

    with area_sync.sync_lock(url) as mine:
        assert mine
        with area_sync.sync_lock(url) as also_mine:
            assert not also_mine  # flock is per open file: a second opening is refused too
        area_sync.sync_areas(url, sessions)
        assert count() == 0
    engine.dispose()


def test_a_failure_is_logged(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    url = f"sqlite:///{tmp_path / 'missing' / 'no-tables.sqlite'}"
    engine = make_engine(url)  # no migrations: the table is missing
    with caplog.at_level(logging.ERROR, logger="server.area_sync"):
        area_sync.sync_areas(url, make_session_factory(engine))
    assert any("syncing the built-in areas failed" in r.getMessage()
               and "areas" in r.getMessage() for r in caplog.records)
    with make_session_factory(engine)() as session, pytest.raises(Exception, match="no such"):
        session.scalar(select(func.count(AreaRow.id)))
    engine.dispose()
