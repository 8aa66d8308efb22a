"""Areas by name: the built-in ones, then those imported and saved by the user."""

from __future__ import annotations

from collections.abc import Callable
from functools import partial

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


def _generators() -> dict[str, Callable[[int], Area]]:
    """Generator of each built-in area by name, taking the layout seed."""
    from areas import facility, offices, platform, powerplant, warehouse

    gens: dict[str, Callable[[int], Area]] = {"maze": build_maze}
    for cfg in (offices.OFFICES_A, offices.OFFICES_B, offices.OFFICES_C):
        gens[cfg.name] = partial(offices.build_offices, cfg)
    for fcfg in (facility.FACILITY_A, facility.FACILITY_B, facility.FACILITY_C):
        gens[fcfg.name] = partial(facility.build_facility, fcfg)
    gens["warehouse"] = warehouse.build_warehouse
    for pcfg in (platform.PLATFORM_A, platform.PLATFORM_B):
        gens[pcfg.name] = partial(platform.build_platform, pcfg)
    gens["powerplant"] = powerplant.build_powerplant
    return gens


_GENERATORS = _generators()


def generate_area(name: str, seed: int) -> Area:
    """A built-in area generated with another layout seed (the registered ones use seed 0).

    Raises:
        UnknownAreaError: when ``name`` is not a built-in area.
    """
    gen = _GENERATORS.get(name.strip().lower())
    if gen is None:
        raise UnknownAreaError(name, sorted(_GENERATORS))
    return gen(seed)


for _name, _gen in _GENERATORS.items():
    # The benchmark's fixed scenes: every built-in area at layout seed 0.
    register_area(_name, partial(_gen, 0))
