"""What the episode runner and a planner exchange: context, observations and plans.

The planner side of the API (the `Planner` base class and the registry) lives in `planners`;
these types live here so that the simulator depends on no planner code.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from sim.camera import CameraConfig
from sim.geometry import FloatArray, Pose
from sim.map_view import MapView
from sim.vehicle import VehicleLimits


class PlanOutcome(enum.StrEnum):
    """How the previous plan ended."""

    NONE = "none"  # first call of the episode
    REACHED = "reached"  # flown to the end, or to the waypoint where the horizon ran out
    # rejected or cut short by the framework's collision check, or stopped in flight because the
    # map found an obstacle by the rest of its path (a safety stop)
    BLOCKED = "blocked"
    INVALID = "invalid"  # malformed waypoints (NaN, outside the area, wrong shape)
    FLYING = "flying"  # asked mid-flight (`Plan.replan_s`); the previous plan is still flown


@dataclass(frozen=True)
class PlannerContext:
    """What a planner learns at reset.

    Attributes:
        area: area name.
        bounds_min, bounds_max: (3,) explorable box, metres.
        start: start pose.
        limits: vehicle limits.
        safety_radius_m: clearance the framework demands between the vehicle centre and any
            unknown or occupied voxel centre (vehicle radius plus a margin for discretisation and
            odometry drift); the map's traversable mask uses it.
        camera: depth camera model.
        rng: the planner's own seeded generator; the only randomness a planner may use.
        indoor: the area's indoor / outdoor class (the FLYBO paper's Table 1 column; an imported
            area's from its geometry, `areas.auto_start`), which a planner may choose its
            settings by, as the FLYBO authors chose theirs per area.
    """

    area: str
    bounds_min: FloatArray
    bounds_max: FloatArray
    start: Pose
    limits: VehicleLimits
    safety_radius_m: float
    camera: CameraConfig
    rng: np.random.Generator
    indoor: bool = True


@dataclass(frozen=True)
class Observation:
    """What a planner sees at each `plan` call.

    Attributes:
        time: simulated seconds since the start.
        pose: estimated pose (odometry, with its drift).
        velocity: (3,) m/s.
        map: read-only occupancy map view with frontier clusters and traversability.
        last_outcome: how the previous plan ended.
    """

    time: float
    pose: Pose
    velocity: FloatArray
    map: MapView
    last_outcome: PlanOutcome


@dataclass(frozen=True)
class Plan:
    """Waypoints to fly, or the end of the exploration.

    Attributes:
        waypoints: (N, 4) x, y, z, yaw in the world frame; the vehicle stops at each one.
        horizon_s: ask again at the first waypoint reached after this many seconds of flight;
            0 asks again at the first waypoint, None at the last one.
        replan_s: ask again after this many seconds of flight even in the middle of a leg
            (None: never mid-leg, the default). The next plan's trajectory then starts from the
            vehicle's moving reference state instead of from rest; if that plan is unusable,
            the current trajectory is flown on.
        keep: only for a plan returned mid-flight: keep flying the current trajectory and ask
            again after `replan_s` seconds; waypoints are ignored.
        done: the planner has nothing left to explore; waypoints are ignored.
        info: free-form diagnostics recorded with the iteration (numbers and strings only).
    """

    waypoints: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 4)))
    horizon_s: float | None = None
    replan_s: float | None = None
    keep: bool = False
    done: bool = False
    info: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def finished(cls, reason: str = "no frontier left") -> Plan:
        return cls(done=True, info={"reason": reason})

    @classmethod
    def keep_flying(cls, replan_s: float, info: dict[str, Any] | None = None) -> Plan:
        """Mid-flight: go on with the current trajectory, ask again after `replan_s`."""
        return cls(replan_s=replan_s, keep=True, info=info or {})


class PlannerLike(Protocol):
    """What the episode runner needs of a planner."""

    def reset(self, ctx: PlannerContext) -> None: ...

    def plan(self, obs: Observation) -> Plan: ...
