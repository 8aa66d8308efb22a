"""What a measure is: one metric of a run, defined once, with the measures it depends on.

A measure is a small class with a registered `name`, the names of the measures it `requires`,
and three steps: `reset` at the start of a run, `update` at every camera frame, and `result` at
the end, which receives the results of the measures it requires. Measures that summarise a run
in numbers declare them as `metrics` (`MetricInfo`); the result file, the database, the
leaderboard and the report list those from the registry (`sim.measures`), so a new metric is
one new measure.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

import numpy as np
import numpy.typing as npt

from areas.area import Area, GroundTruth
from sim.config import EpisodeConfig
from sim.map_view import MappingStack
from sim.result import RunStatus
from sim.tsdf import TsdfVolume

ProgressCallback = Callable[[float, float], None]


@dataclass
class EpisodeCounters:
    """What the loop counts as it flies; measures read it, only the loop writes it."""

    path_length_m: float = 0.0
    collisions: int = 0
    safety_stops: int = 0
    planning_ms: list[float] = field(default_factory=list)
    # Planning time charged to the simulated clock per call, seconds (0 when nothing is charged).
    charged_s: list[float] = field(default_factory=list)


@dataclass
class EpisodeView:
    """The run as measures see it: the scene, its truth, the maps and the loop's counters.

    Attributes:
        distance_to_surface: exact distance from points (N, 3) to the area's mesh, metres.
        progress: called with (time s, explored volume m³) about once per simulated second.
    """

    area: Area
    truth: GroundTruth
    config: EpisodeConfig
    seed: int
    mapping: MappingStack
    tsdf: TsdfVolume
    counters: EpisodeCounters
    distance_to_surface: Callable[[npt.NDArray[np.floating]], npt.NDArray[np.floating]]
    progress: ProgressCallback | None = None


@dataclass(frozen=True)
class EpisodeEnd:
    """How the run ended, given to `Measure.result`.

    Attributes:
        t_end: the run's time limit, s; an early finish keeps its curves flat up to it.
        simulated_until: the simulated time at the end of the loop, s.
    """

    status: RunStatus
    t_end: float
    simulated_until: float

    @property
    def flat_to_end(self) -> bool:
        """After a planner's early finish the map no longer changes: series stay flat."""
        return self.status is RunStatus.SUCCEEDED


@dataclass(frozen=True)
class MetricInfo:
    """One number a measure reports for a run.

    Attributes:
        key: the name in `result.json`'s `metrics` block and in the database.
        label: a short human label (tables and pages).
        unit: SI unit, "" when dimensionless.
        higher_is_better: the direction a ranking sorts in.
        leaderboard: shown on the leaderboard by default.
        fmt: a Python format spec for tables.
    """

    key: str
    label: str
    unit: str = ""
    higher_is_better: bool = True
    leaderboard: bool = False
    fmt: str = ".3f"
    aggregate: Literal["mean", "sum", "max"] = "mean"


class Measure(ABC):
    """One metric of a run (see the module docstring)."""

    name: ClassVar[str]
    requires: ClassVar[tuple[str, ...]] = ()
    metrics: ClassVar[tuple[MetricInfo, ...]] = ()

    def reset(self, ep: EpisodeView) -> None:  # noqa: B027 - most measures keep no state
        """Called once before the first frame."""

    def update(self, ep: EpisodeView, stamp: float) -> None:  # noqa: B027
        """Called at every camera frame, `stamp` seconds into the run."""

    @abstractmethod
    def result(self, ep: EpisodeView, end: EpisodeEnd, done: Mapping[str, Any]) -> Any:
        """The measure's value; `done` holds the results of the measures in `requires`."""

    def scalars(self, value: Any) -> dict[str, float | None]:
        """The numbers of `metrics`, read off this measure's `result` (None: undefined)."""
        if not self.metrics:
            return {}
        if len(self.metrics) != 1:
            raise TypeError(f"{self.name} reports several metrics: it must define scalars()")
        return {self.metrics[0].key: _finite_or_none(value)}


def _finite_or_none(value: Any) -> float | None:
    if value is None:
        return None
    if isinstance(value, int | np.integer) and not isinstance(value, bool):
        return int(value)  # counts stay whole numbers in the result file
    number = float(value)
    return number if np.isfinite(number) else None
