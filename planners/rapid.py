"""Rapid frontier exploration (Cieslewski, Kaufmann, Scaramuzza, IROS 2017).

While frontier voxels lie in the camera's current field of view, fly toward the one that needs
the least change of the current velocity direction, and keep flying: the planner is asked again
every `replan_period_s` of flight, and each new trajectory starts from the moving state, so the
vehicle does not stop between decisions. The goal is the farthest point toward that frontier the
vehicle can reach in a straight line through traversable space. With no usable frontier in view
it falls back to Classic's nearest frontier by path length (`planners.classic`): classic-v1's
(rapid-v1) or classic-v2's (rapid-v2), the only difference between the two versions.

Some frontier voxels never clear (their unknown neighbours cannot be seen from traversable
space). A frontier voxel that has been in view, close by, at `give_up_views` decisions and is still
a frontier is given up, as is the target of a direct flight that came to rest without clearing
it; this plays the part of Classic's giving up a target after visiting its viewpoint.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np
import numpy.typing as npt
from pydantic import Field

from planners.api import Observation, Plan, Planner, PlannerConfig, PlannerContext, PlanOutcome
from planners.classic import ClassicConfig, ClassicPlanner, ClassicV2Config
from planners.frontiers import frontiers_in_view
from planners.lines import farthest_clear_point, reachable_lengths
from planners.search import IndexArray

FloatArray = npt.NDArray[np.float64]


class RapidConfig(PlannerConfig):
    """Rapid's settings (sources in comments)."""

    # Rapid decides at every map update; the default preset fuses the map at 5 Hz.
    replan_period_s: float = Field(0.2, gt=0.0)
    # Our choice: about twice the braking distance at full speed (1.5² / (2 * 2.5) = 0.45 m),
    # so a direct goal does not make the vehicle brake hard; 0.5 m lost 20 points of coverage
    # on two of five MAZE seeds (docs/PERFORMANCE.md).
    min_goal_distance_m: float = Field(1.0, gt=0.0)
    # Our choice: below this speed the heading stands for the velocity direction.
    min_speed_mps: float = Field(0.3, ge=0.0)
    # Our choice: how many of the best-aligned reachable candidates get the final check.
    max_candidates: int = Field(16, ge=1)
    # As Classic: frontier groups smaller than this are noise (counted within sensor range).
    min_cluster_size: int = Field(50, ge=1)
    # As Classic's viewpoints: a frontier seen more steeply than this from the vehicle lies near
    # the floor or the ceiling, where flying toward it does not clear it.
    max_elevation_deg: float = Field(30.0, gt=0.0, lt=90.0)
    give_up_radius_voxels: int = Field(5, ge=0)
    # Our choice: ten decisions (2 s at the default period) looking at a frontier voxel from
    # within `give_up_range_m` without clearing it.
    give_up_views: int = Field(10, ge=1)
    give_up_range_m: float = Field(3.0, gt=0.0)
    # Our choice: stop short of the edge of traversable space by this much, so that the next
    # map update (noise, a wall seen closer) does not leave the vehicle outside it.
    goal_margin_m: float = Field(0.2, ge=0.0)
    # Our choice: when the fallback finds no reachable frontier although frontiers remain,
    # turn on the spot (a quarter turn each time) to look again before giving up.
    look_around_turns: int = Field(4, ge=0)
    # The fallback is Classic with its own defaults (classic-v1's).
    fallback: ClassicConfig = ClassicConfig()


class RapidV2Config(RapidConfig):
    """rapid-v2: classic-v2 as the fallback."""

    fallback: ClassicV2Config = ClassicV2Config()


class RapidPlanner(Planner):
    """The code of every Rapid version; `config_model` picks the version."""

    config_model: ClassVar[type[RapidConfig]] = RapidConfig
    config: RapidConfig

    def reset(self, ctx: PlannerContext) -> None:
        super().reset(ctx)
        self._classic = ClassicPlanner(self.config.fallback)
        self._classic.reset(ctx)
        self._given_up: npt.NDArray[np.bool_] | None = None
        self._views: npt.NDArray[np.uint16] | None = None  # decisions each voxel was seen at
        self._target: IndexArray | None = None  # the frontier voxel of the last direct goal
        self._turns = 0  # quarter turns since the fallback last found a frontier

    def plan(self, obs: Observation) -> Plan:
        cfg, view = self.config, obs.map
        if self._given_up is None or self._views is None:
            self._given_up = np.zeros(view.shape, dtype=np.bool_)
            self._views = np.zeros(view.shape, dtype=np.uint16)
        self._give_up_if_stuck(obs)
        direct = self._direct_goal(obs)
        if direct is not None:
            goal, target, angle = direct
            self._target = target
            return Plan(goal[None], replan_s=cfg.replan_period_s,
                        info={"mode": "direct", "angle_deg": float(np.degrees(angle))})
        self._target = None
        if obs.last_outcome == PlanOutcome.FLYING:
            return Plan.keep_flying(cfg.replan_period_s, info={"mode": "keep"})
        fallback = self._classic.plan(obs)
        if fallback.done:
            stuck = fallback.info.get("reason") != "no frontier left"
            if stuck and self._turns < cfg.look_around_turns:
                self._turns += 1
                turn = np.array([[*obs.pose.position, obs.pose.yaw + np.pi / 2.0]])
                return Plan(turn, info={"mode": "look around", "turns": self._turns})
            return fallback
        self._turns = 0
        return Plan(fallback.waypoints, horizon_s=fallback.horizon_s,
                    replan_s=cfg.replan_period_s, info={**fallback.info, "mode": "classic"})

    def _give_up_if_stuck(self, obs: Observation) -> None:
        """Came to rest on a direct goal whose frontier is still there: give it up."""
        t = self._target
        if t is None or self._given_up is None or obs.last_outcome == PlanOutcome.FLYING:
            return
        if obs.map.frontier[t[0], t[1], t[2]]:
            r = self.config.give_up_radius_voxels
            lo = np.maximum(t - r, 0)
            hi = t + r + 1
            self._given_up[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]] = True

    def _count_views(self, idx: IndexArray, offsets: FloatArray) -> None:
        """Count a decision for each frontier voxel in view and close; give up the stubborn."""
        assert self._views is not None and self._given_up is not None
        close = idx[np.linalg.norm(offsets, axis=1) <= self.config.give_up_range_m]
        i, j, k = close[:, 0], close[:, 1], close[:, 2]
        self._views[i, j, k] = np.minimum(self._views[i, j, k].astype(np.int64) + 1,
                                          np.iinfo(np.uint16).max)
        stubborn = self._views[i, j, k] >= self.config.give_up_views
        self._given_up[i[stubborn], j[stubborn], k[stubborn]] = True

    def _direct_goal(self, obs: Observation) -> tuple[FloatArray, IndexArray, float] | None:
        """(4,) goal, the frontier voxel it heads for, and the turn it needs (rad)."""
        cfg, view = self.config, obs.map
        assert self._given_up is not None
        idx, offsets = frontiers_in_view(view, obs.pose, self.context.camera,
                                         min_group_size=cfg.min_cluster_size)
        if len(idx) == 0:
            return None
        elevation = np.arctan2(np.abs(offsets[:, 2]), np.linalg.norm(offsets[:, :2], axis=1))
        self._count_views(idx, offsets)
        keep = (~self._given_up[idx[:, 0], idx[:, 1], idx[:, 2]]
                & (elevation <= np.radians(cfg.max_elevation_deg)))
        idx, offsets = idx[keep], offsets[keep]
        if len(idx) == 0:
            return None
        velocity = np.asarray(obs.velocity, dtype=np.float64)
        speed = float(np.linalg.norm(velocity))
        if speed >= max(cfg.min_speed_mps, 1e-9):
            reference = velocity / speed
        else:
            reference = np.array([np.cos(obs.pose.yaw), np.sin(obs.pose.yaw), 0.0])
        dirs = offsets / np.linalg.norm(offsets, axis=1)[:, None]
        angles = np.arccos(np.clip(dirs @ reference, -1.0, 1.0))
        here = np.asarray(obs.pose.position, dtype=np.float64)
        reach = reachable_lengths(view, here, here + offsets)
        if np.all(reach < 0.0):
            return None  # not even the start is usable: leave it to the fallback
        usable = np.flatnonzero(reach >= cfg.min_goal_distance_m + cfg.goal_margin_m)
        order = usable[np.argsort(angles[usable], kind="stable")][: cfg.max_candidates]
        for n in order:
            point = farthest_clear_point(view, here, here + offsets[n])
            if point is None:
                continue
            length = float(np.linalg.norm(point - here))
            if length - cfg.goal_margin_m < cfg.min_goal_distance_m:
                continue
            point = here + (point - here) * (length - cfg.goal_margin_m) / length
            yaw = float(np.arctan2(offsets[n, 1], offsets[n, 0]))
            return np.array([*point, yaw]), idx[n], float(angles[n])
        return None


class Rapid(RapidPlanner):
    """rapid-v1."""

    config_model = RapidConfig
    config: RapidConfig


class RapidV2(RapidPlanner):
    """rapid-v2."""

    config_model = RapidV2Config
    config: RapidV2Config
