"""The planner API: a small agent with `reset(ctx)` and `plan(obs) -> Plan`.

The framework owns everything around a planner: it checks each plan's path against the map,
turns waypoints into a jerk-limited trajectory, flies it, maps, and times every `plan` call.
The data types exchanged are defined in `sim.interface` and re-exported here.
"""

from __future__ import annotations

import abc
from typing import ClassVar

import numpy as np
import numpy.typing as npt
from pydantic import BaseModel, ConfigDict

from sim.geometry import FloatArray
from sim.interface import Observation, Plan, PlannerContext, PlanOutcome

__all__ = [
    "BoolGrid",
    "FloatArray",
    "IntArray",
    "Observation",
    "Plan",
    "PlanOutcome",
    "Planner",
    "PlannerConfig",
    "PlannerContext",
]

# The array types of the planners' signatures, for planners to import from here. `FloatArray`
# is the simulator's (`sim.geometry`); the other two belong beside it in `sim` as well, and are
# defined here until they are.
BoolGrid = npt.NDArray[np.bool_]
IntArray = npt.NDArray[np.int64]


class PlannerConfig(BaseModel):
    """Base of every planner's configuration: frozen, unknown keys rejected."""

    model_config = ConfigDict(frozen=True, extra="forbid")


class Planner(abc.ABC):
    """Base class of every planner. Subclasses set `config_model` and implement `plan`."""

    config_model: ClassVar[type[PlannerConfig]] = PlannerConfig

    def __init__(self, config: PlannerConfig | None = None) -> None:
        self.config = config if config is not None else self.config_model()
        self.ctx: PlannerContext | None = None

    def reset(self, ctx: PlannerContext) -> None:
        """Start a new episode; subclasses that keep state extend this and call super()."""
        self.ctx = ctx

    @property
    def context(self) -> PlannerContext:
        if self.ctx is None:
            raise RuntimeError(f"{type(self).__name__}.plan called before reset")
        return self.ctx

    @abc.abstractmethod
    def plan(self, obs: Observation) -> Plan:
        """Next waypoints given the current observation."""
