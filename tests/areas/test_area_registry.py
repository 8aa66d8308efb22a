"""Area registry: names, case-insensitive loading, unknown names."""

from __future__ import annotations

import numpy as np
import pytest

import areas
from areas import registry
from areas.maze import build_maze


def test_maze_is_registered_and_cached() -> None:
    assert "maze" in areas.area_names()
    maze = areas.load_area("maze")
    assert isinstance(maze, areas.Area)
    assert areas.load_area("MAZE") is maze
    assert areas.load_area(" Maze ") is maze
    np.testing.assert_array_equal(maze.triangles, build_maze(seed=0).triangles)


def test_unknown_area_lists_known_names() -> None:
    with pytest.raises(areas.UnknownAreaError, match=r"unknown area 'foo'; known areas: .*maze"):
        areas.load_area("foo")
    assert issubclass(areas.UnknownAreaError, ValueError)


def test_register_area(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(registry, "_builders", dict(registry._builders))
    monkeypatch.setattr(registry, "_loaded", {})
    calls: list[int] = []

    def build() -> areas.Area:
        calls.append(1)
        return build_maze(seed=7)

    registry.register_area("Maze7", build)
    assert "maze7" in registry.area_names()
    assert len(registry.area_names()) == 12
    first = areas.load_area("maze7")
    assert areas.load_area("MAZE7") is first
    assert len(calls) == 1
