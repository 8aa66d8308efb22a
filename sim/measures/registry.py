"""The measure registry: every metric of a run is one `Measure` class registered here."""

from __future__ import annotations

import difflib

from sim.measures.base import Measure, MetricInfo

_MEASURES: dict[str, type[Measure]] = {}


class UnknownMeasureError(ValueError):
    """No measure is registered under the requested name."""


def register_measure(cls: type[Measure]) -> type[Measure]:
    """Register `cls` under `cls.name`; usable as a class decorator."""
    name = getattr(cls, "name", "")
    if not name:
        raise ValueError(f"{cls.__qualname__} has no name")
    if name in _MEASURES and _MEASURES[name] is not cls:
        raise ValueError(f"a measure named {name!r} is already registered")
    keys = {m.key for other in _MEASURES.values() if other is not cls for m in other.metrics}
    clash = [m.key for m in cls.metrics if m.key in keys]
    if clash:
        raise ValueError(f"{name}: metric keys already reported by another measure: {clash}")
    _MEASURES[name] = cls
    return cls


def measure_names() -> list[str]:
    """Every registered measure, in an order where each follows the measures it requires."""
    order: list[str] = []
    visiting: set[str] = set()

    def visit(name: str, needed_by: str | None) -> None:
        if name in order:
            return
        if name not in _MEASURES:
            close = difflib.get_close_matches(name, _MEASURES, n=3)
            hint = f"; did you mean {', '.join(close)}?" if close else ""
            raise UnknownMeasureError(
                f"measure {needed_by!r} requires unknown measure {name!r}{hint}")
        if name in visiting:
            raise ValueError(f"measures require each other in a cycle through {name!r}")
        visiting.add(name)
        for dep in _MEASURES[name].requires:
            visit(dep, name)
        visiting.discard(name)
        order.append(name)

    for name in _MEASURES:
        visit(name, None)
    return order


def make_measures() -> list[Measure]:
    """A fresh instance of every registered measure, dependencies first."""
    return [_MEASURES[name]() for name in measure_names()]


def metric_infos() -> list[MetricInfo]:
    """Every number the measures report, in registry order."""
    return [m for name in measure_names() for m in _MEASURES[name].metrics]


def metric_info(key: str) -> MetricInfo:
    """The metric reported under `key`."""
    for info in metric_infos():
        if info.key == key:
            return info
    known = [m.key for m in metric_infos()]
    close = difflib.get_close_matches(key, known, n=3)
    hint = f" (did you mean {', '.join(close)}?)" if close else ""
    raise UnknownMeasureError(f"unknown metric {key!r}{hint}; known: {', '.join(known)}")
