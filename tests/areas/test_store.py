"""Saving imported areas and finding them by name."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from areas import UnknownAreaError, load_area
from areas.maze import build_maze
from areas.registry import all_area_names, area_names, store_area
from areas.store import AreaStoreError, areas_dir, load_stored_area, save_area


@pytest.fixture(autouse=True)
def data_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv("FLYBO_DATA_DIR", str(tmp_path))
    return tmp_path


def test_round_trip_and_lookup_by_name(data_dir: Path) -> None:
    area = replace(build_maze(seed=3), name="my-maze")
    store_area(area)
    assert (data_dir / "areas" / "my-maze.npz").is_file()
    back = load_area("My-Maze")
    np.testing.assert_array_equal(back.vertices, area.vertices)
    np.testing.assert_array_equal(back.triangles, area.triangles)
    np.testing.assert_array_equal(back.bounds_min, area.bounds_min)
    np.testing.assert_array_equal(back.start.position, area.start.position)
    assert back.start.yaw == area.start.yaw
    assert (back.plateau_s, back.voxel_size, back.info) == (area.plateau_s, area.voxel_size,
                                                            area.info)
    assert back.content_hash == area.content_hash
    assert all_area_names() == sorted([*area_names(), "my-maze"])


def test_unknown_names_list_stored_areas() -> None:
    store_area(replace(build_maze(seed=1), name="hall"))
    with pytest.raises(UnknownAreaError, match=r"known areas: .*\bhall, maze\b"):
        load_area("nowhere")


def test_existing_names_are_kept_unless_overwriting() -> None:
    first = replace(build_maze(seed=1), name="hall")
    store_area(first)
    second = replace(build_maze(seed=2), name="hall", _hash=None)
    with pytest.raises(AreaStoreError, match="already exists"):
        store_area(second)
    assert load_stored_area("hall").content_hash == first.content_hash  # nothing lost
    store_area(second, overwrite=True)
    assert load_stored_area("hall").content_hash == second.content_hash


def test_bad_names_and_built_in_names_are_refused() -> None:
    with pytest.raises(AreaStoreError, match="built-in"):
        store_area(build_maze(seed=0))
    with pytest.raises(AreaStoreError, match="invalid area name"):
        save_area(replace(build_maze(seed=0), name="Bad Name"))
    assert not areas_dir().exists() or not any(areas_dir().iterdir())


def test_corrupt_files_give_a_clear_error() -> None:
    areas_dir().mkdir(parents=True)
    (areas_dir() / "broken.npz").write_bytes(b"not a zip")
    with pytest.raises(AreaStoreError, match="unreadable stored area"):
        load_stored_area("broken")
    with pytest.raises(AreaStoreError, match="no stored area"):
        load_stored_area("absent")
