"""Every folder comes from `Settings`, with one default per root that the areas library shares."""

from __future__ import annotations

from pathlib import Path

import pytest

from areas.cache import cache_dir
from areas.store import areas_dir
from server.settings import Settings


@pytest.fixture
def home(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A fresh home folder, no FLYBO_* folders set, and a working directory elsewhere."""
    home = tmp_path / "home"
    home.mkdir()
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.delenv("FLYBO_DATA_DIR", raising=False)
    monkeypatch.delenv("FLYBO_CACHE_DIR", raising=False)
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    return home


def test_the_defaults_are_in_the_home_folder_not_the_working_directory(home: Path) -> None:
    settings = Settings()
    data = home / ".local" / "share" / "flybo"
    assert settings.resolved_data_dir == data.resolve()
    assert settings.resolved_cache_dir == (home / ".cache" / "flybo").resolve()
    assert settings.areas_dir == data.resolve() / "areas"
    assert settings.artifacts == (data.resolve() / "artifacts").as_uri()
    assert settings.db_url == f"sqlite:///{data.resolve() / 'flybo.sqlite'}"
    assert settings.artifact_cache_dir == (home / ".cache" / "flybo" / "artifacts").resolve()
    # The areas library, which cannot import the settings, finds the same folders.
    assert areas_dir().resolve() == settings.areas_dir
    assert cache_dir().resolve() == settings.resolved_cache_dir


def test_the_environment_moves_both_roots(home: Path, tmp_path: Path,
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("FLYBO_DATA_DIR", str(tmp_path / "d"))
    monkeypatch.setenv("FLYBO_CACHE_DIR", str(tmp_path / "c"))
    settings = Settings()
    assert settings.areas_dir == (tmp_path / "d" / "areas").resolve()
    assert settings.broker_folder == (tmp_path / "d" / "broker").resolve()
    assert settings.artifact_cache_dir == (tmp_path / "c" / "artifacts").resolve()
    assert areas_dir().resolve() == settings.areas_dir
    assert cache_dir().resolve() == settings.resolved_cache_dir


def test_the_fields_move_them_too(home: Path, tmp_path: Path) -> None:
    settings = Settings(data_dir=tmp_path / "d", cache_dir=tmp_path / "c")
    assert settings.areas_dir == (tmp_path / "d" / "areas").resolve()
    assert settings.artifacts_dir == (tmp_path / "d" / "artifacts").resolve()
    assert settings.artifact_cache_dir == (tmp_path / "c" / "artifacts").resolve()
    assert not (home / ".local").exists()
