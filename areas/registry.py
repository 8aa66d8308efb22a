"""Areas by name: the built-in ones, then those imported and saved by the user."""

from __future__ import annotations

from collections.abc import Callable

from areas.area import Area
from areas.maze import build_maze
from areas.store import AreaStoreError, load_stored_area, save_area, stored_area_names

_builders: dict[str, Callable[[], Area]] = {}
_loaded: dict[str, Area] = {}


class UnknownAreaError(ValueError):
    """Raised for an area name that is not registered."""

    def __init__(self, name: str, known: list[str]) -> None:
        super().__init__(f"unknown area {name!r}; known areas: {', '.join(known)}")
        self.name = name
        self.known = known


def register_area(name: str, builder: Callable[[], Area]) -> None:
    """Register ``builder`` under ``name`` (stored lower case); a later call replaces it."""
    key = name.lower()
    _builders[key] = builder
    _loaded.pop(key, None)


def area_names() -> list[str]:
    """Built-in area names, sorted."""
    return sorted(_builders)


def all_area_names() -> list[str]:
    """Built-in and stored area names, sorted."""
    return sorted(set(_builders) | set(stored_area_names()))


def store_area(area: Area, *, overwrite: bool = False) -> None:
    """Save an imported area so that `load_area` finds it; built-in names are reserved."""
    if area.name in _builders:
        raise AreaStoreError(f"{area.name!r} is a built-in area; choose another name")
    save_area(area, overwrite=overwrite)


def load_area(name: str) -> Area:
    """The area registered under ``name`` (case-insensitive), built once per process.

    Raises:
        UnknownAreaError: when no area has that name.
    """
    key = name.strip().lower()
    area = _loaded.get(key)
    if area is not None:
        return area
    builder = _builders.get(key)
    if builder is not None:
        area = builder()
        _loaded[key] = area
        return area
    if key in stored_area_names():
        return load_stored_area(key)  # not memoised: the file may be replaced
    raise UnknownAreaError(name, all_area_names())


register_area("maze", lambda: build_maze(seed=0))
