"""Classic frontier exploration (Yamauchi, CIRA 1997), in 3D.

Fly to the nearest frontier by path length: a Dijkstra search through traversable voxels stops at
the first viewpoint of any frontier cluster; the path is shortened by line-of-sight checks and
flown with the camera looking along each leg, then at the frontier. Replans at every waypoint.
Frontier voxels that stay frontiers after being looked at from their viewpoint twice are given up.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from pydantic import Field

from planners.api import Observation, Plan, Planner, PlannerConfig, PlannerContext
from planners.give_up import GiveUpTracker
from planners.search import DistanceField, IndexArray, shortcut
from planners.viewpoints import frontier_viewpoints, ring_offsets
from planners.waypoints import nearest_traversable, path_waypoints


class ClassicConfig(PlannerConfig):
    """Classic's settings."""

    min_cluster_size: int = Field(50, ge=1, description="smaller frontier clusters are noise")
    view_distances_m: tuple[float, ...] = (1.0, 2.0, 3.5)
    view_height_offsets_m: tuple[float, ...] = (0.0, -0.5, 0.5)
    view_directions: int = Field(8, ge=1)
    samples_per_cluster: int = Field(16, ge=1)
    max_view_elevation_deg: float = Field(30.0, gt=0.0, lt=90.0)
    give_up_after: int = Field(2, ge=1, description="visits that left the target a frontier")
    give_up_radius_voxels: int = Field(2, ge=0)


class Classic(Planner):
    config_model = ClassicConfig
    config: ClassicConfig

    def reset(self, ctx: PlannerContext) -> None:
        super().reset(ctx)
        cfg = self.config
        self._offsets = ring_offsets(
            cfg.view_distances_m, cfg.view_height_offsets_m, cfg.view_directions
        )
        self._give_up = GiveUpTracker(cfg.give_up_after, cfg.give_up_radius_voxels)
        self._goal: IndexArray | None = None
        self._target: IndexArray | None = None

    def plan(self, obs: Observation) -> Plan:
        cfg, view = self.config, obs.map
        here = view.world_to_index(obs.pose.position[None])[0]
        given_up = self._give_up.update(here, self._goal, self._target, obs)
        clusters = view.frontier_clusters(cfg.min_cluster_size)
        if not clusters:
            return Plan.finished("no frontier left")
        start = nearest_traversable(view.traversable, here)
        if start is None:
            return Plan.finished("the vehicle is not in traversable space")
        viewpoints = frontier_viewpoints(
            view,
            clusters,
            self._offsets,
            samples_per_cluster=cfg.samples_per_cluster,
            max_elevation_rad=np.radians(cfg.max_view_elevation_deg),
            max_range_m=self.context.camera.max_range_m,
            excluded=given_up,
        )
        if len(viewpoints) == 0:
            return Plan.finished("no frontier can be seen from traversable space")
        goals = np.zeros(view.shape, dtype=np.bool_)
        goals[viewpoints.voxels[:, 0], viewpoints.voxels[:, 1], viewpoints.voxels[:, 2]] = True
        field = DistanceField(view.traversable, start, view.voxel_size, goals=goals)
        goal = field.nearest_goal
        if goal is None:
            return Plan.finished("no frontier viewpoint is reachable")
        which = np.flatnonzero(np.all(viewpoints.voxels == goal, axis=1))[0]
        self._goal, self._target = goal, viewpoints.targets[which]
        path = shortcut(field.path_to(goal), view.traversable)
        target_world = view.index_to_world(self._target[None])[0]
        waypoints = path_waypoints(view, path, obs.pose.position, target_world)
        return Plan(
            waypoints,
            horizon_s=0.0,
            info={"clusters": len(clusters), "path_m": field.distance_to(goal)},
        )


def frontier_fallback(fallback: Classic, obs: Observation, **info: Any) -> Plan:
    """Classic's nearest frontier as another planner's fallback: Classic's plan, marked
    `mode: classic` with `info` added, or Classic's own end of the exploration."""
    plan = fallback.plan(obs)
    if plan.done:
        return plan
    merged = {**plan.info, "mode": "classic", **info}
    return Plan(plan.waypoints, horizon_s=plan.horizon_s, info=merged)
