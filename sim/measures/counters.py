"""Measures the loop counts as it flies: path length, collisions, safety stops, planning."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from sim.measures.base import EpisodeEnd, EpisodeView, Measure, MetricInfo


class _Count(Measure):
    """A number the loop counts (an attribute of `EpisodeCounters`), reported as it stands at
    the end of the run."""

    counter: ClassVar[str]

    def result(self, ep: EpisodeView, end: EpisodeEnd, done: Mapping[str, Any]) -> Any:
        return getattr(ep.counters, self.counter)


class PathLength(_Count):
    """Length of the true path flown, metres (summed over physics steps)."""

    name, counter = "path_length", "path_length_m"
    metrics = (MetricInfo("path_length_m", "path length", unit="m", higher_is_better=False,
                          fmt=".1f"),)


class Collisions(_Count):
    """Contacts of the vehicle with the scene (a contact ends the run)."""

    name, counter = "collisions", "collisions"
    metrics = (MetricInfo("collisions", "collisions", higher_is_better=False, fmt="d",
                          aggregate="sum"),)


class SafetyStops(_Count):
    """Flights braked because the map found an obstacle by the rest of their path."""

    name, counter = "safety_stops", "safety_stops"
    metrics = (MetricInfo("safety_stops", "safety stops", higher_is_better=False, fmt="d",
                          aggregate="sum"),)


@dataclass(frozen=True)
class PlanningTimes:
    """Per `plan` call: `wall_ms` (N,) wall time in ms, `charged_s` (N,) seconds charged to the
    simulated clock."""

    wall_ms: npt.NDArray[np.float64]
    charged_s: npt.NDArray[np.float64]

    @property
    def iterations(self) -> int:
        return len(self.wall_ms)


class Planning(Measure):
    """The planner's calls: how many, their wall time and the time charged for them."""

    name = "planning"
    metrics = (MetricInfo("iterations", "iterations", fmt="d"),)

    def result(self, ep: EpisodeView, end: EpisodeEnd, done: Mapping[str, Any]) -> PlanningTimes:
        return PlanningTimes(np.array(ep.counters.planning_ms), np.array(ep.counters.charged_s))

    def scalars(self, value: Any) -> dict[str, float | None]:
        times: PlanningTimes = value
        return {"iterations": times.iterations}
