"""A learned policy as a planner: the observations and actions of the Gymnasium environment
(`flybo.envs`), computed from what any planner sees, so that a policy trained there can be
uploaded and ranked like any other planner (NumPy only: no Gymnasium needed here).

Observations (a dict of arrays; `PolicyConfig.keys` chooses which):

- ``pose``: (7,) float32, the estimated x, y, z (m), yaw (rad) and velocity (m/s, world frame);
- ``occupancy``: (C, C, H) uint8, the map states (0 unknown, 1 free, 2 occupied) in an
  axis-aligned box of C x C x H voxels centred on the vehicle's voxel; outside the area counts
  as occupied;
- ``frontier``: (C, C, H) uint8, 1 on frontier voxels (free beside unknown) in the same box.

Actions: (4,) float32 in [-1, 1]. With ``action="waypoint"`` they are a relative waypoint, x,
y, z scaled by `PolicyConfig.max_step_m` and yaw by pi, flown by the framework's own check and
trajectory. With ``action="velocity"`` they are a velocity (scaled by the vehicle's v_max) and
a yaw rate (scaled by yaw_rate_max), flown as the waypoint they reach in
`PolicyConfig.step_s`. Waypoints outside the area are clipped to it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Literal

import numpy as np
import numpy.typing as npt
from pydantic import Field

from planners.api import Observation, Plan, Planner, PlannerConfig, PlannerContext
from sim.occupancy import VoxelState

ObservationKey = Literal["pose", "occupancy", "frontier"]
PolicyObservation = dict[str, npt.NDArray[np.generic]]
Policy = Callable[[Mapping[str, npt.NDArray[np.generic]]], npt.ArrayLike]


class PolicyConfig(PlannerConfig):
    """How observations are built and actions read."""

    keys: tuple[ObservationKey, ...] = ("pose", "occupancy", "frontier")
    crop_xy: int = Field(64, ge=4, le=256, description="voxels across the crop, x and y")
    crop_z: int = Field(16, ge=2, le=64, description="voxels of the crop in z")
    action: Literal["waypoint", "velocity"] = "waypoint"
    max_step_m: float = Field(3.0, gt=0.0, description="waypoint action: metres at 1.0")
    step_s: float = Field(1.0, gt=0.0, description="velocity action: seconds flown per action")


def _crop(grid: npt.NDArray[np.uint8], centre: npt.NDArray[np.int64], size: tuple[int, int, int],
          outside: int) -> npt.NDArray[np.uint8]:
    out = np.full(size, outside, dtype=np.uint8)
    lo = centre - np.array(size) // 2
    src_lo = np.maximum(lo, 0)
    src_hi = np.minimum(lo + np.array(size), grid.shape)
    if np.any(src_hi <= src_lo):
        return out
    dst_lo = src_lo - lo
    dst_hi = dst_lo + (src_hi - src_lo)
    out[dst_lo[0]:dst_hi[0], dst_lo[1]:dst_hi[1], dst_lo[2]:dst_hi[2]] = \
        grid[src_lo[0]:src_hi[0], src_lo[1]:src_hi[1], src_lo[2]:src_hi[2]]
    return out


def observe(obs: Observation, cfg: PolicyConfig) -> PolicyObservation:
    """The policy's observation of what the planner sees."""
    out: PolicyObservation = {}
    p = obs.pose.position
    if "pose" in cfg.keys:
        out["pose"] = np.array([*p, obs.pose.yaw, *obs.velocity], dtype=np.float32)
    size = (cfg.crop_xy, cfg.crop_xy, cfg.crop_z)
    if "occupancy" in cfg.keys or "frontier" in cfg.keys:
        centre = np.asarray(obs.map.world_to_index(p), dtype=np.int64)
        if "occupancy" in cfg.keys:
            out["occupancy"] = _crop(obs.map.state, centre, size, int(VoxelState.OCCUPIED))
        if "frontier" in cfg.keys:
            out["frontier"] = _crop(obs.map.frontier.view(np.uint8), centre, size, 0)
    return out


def action_to_plan(action: npt.ArrayLike, obs: Observation, ctx: PlannerContext,
                   cfg: PolicyConfig) -> Plan:
    """The plan an action stands for (see the module docstring)."""
    a = np.clip(np.asarray(action, dtype=np.float64).reshape(4), -1.0, 1.0)
    p = obs.pose.position
    if cfg.action == "waypoint":
        delta, dyaw = a[:3] * cfg.max_step_m, a[3] * math.pi
    else:
        delta, dyaw = a[:3] * ctx.limits.v_max * cfg.step_s, \
            a[3] * ctx.limits.yaw_rate_max * cfg.step_s
    target = np.clip(p + delta, ctx.bounds_min, ctx.bounds_max)
    yaw = math.remainder(obs.pose.yaw + dyaw, 2.0 * math.pi)
    return Plan(waypoints=np.array([[*target, yaw]]))


class PolicyPlanner(Planner):
    """Runs `policy` (observation dict -> action) as a planner. Subclass it with a `policy`
    method (an uploaded planner), or pass the callable to the constructor."""

    config_model = PolicyConfig

    def __init__(self, config: PlannerConfig | None = None, policy: Policy | None = None) -> None:
        super().__init__(config)
        self._policy = policy

    @property
    def cfg(self) -> PolicyConfig:
        assert isinstance(self.config, PolicyConfig)
        return self.config

    def policy(self, observation: Mapping[str, npt.NDArray[np.generic]]) -> npt.ArrayLike:
        if self._policy is None:
            raise TypeError(f"{type(self).__name__} has no policy: pass one or override policy()")
        return self._policy(observation)

    def plan(self, obs: Observation) -> Plan:
        return action_to_plan(self.policy(observe(obs, self.cfg)), obs, self.context, self.cfg)
