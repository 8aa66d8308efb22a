"""Classic frontier exploration (Yamauchi, CIRA 1997), in 3D.

Fly to the nearest frontier by path length: a Dijkstra search through traversable voxels stops at
the first viewpoint of any frontier cluster; the path is shortened by line-of-sight checks and
flown with the camera looking along each leg, then at the frontier. Replans at every waypoint.
Frontier voxels that stay frontiers after being looked at from their viewpoint twice are given up.

Versions: classic-v1 (`ClassicConfig`) takes a viewpoint that sees the frontier voxel, gives up
each target alone, and searches from the nearest traversable voxel within three of the
vehicle's. classic-v2 (`ClassicV2Config`) takes only viewpoints that see into the unknown beside
the frontier voxel (`planners.viewpoints.sees_into_unknown`); keeps Yamauchi's list of visited
frontiers: every frontier voxel the camera looked into from a reached viewpoint counts as
visited, besides the target (`planners.give_up`); and where the map no longer lets the vehicle
stand, it searches from the traversable voxels the framework lets it escape to
(`planners.waypoints.escape_starts`), trying the next pocket when one leads nowhere. classic-v3
(`ClassicV3Config`) shortcuts the path from the vehicle's exact position, where v2 could fly back
to its voxel's centre and ask again there for ever
(`planners.waypoints.shortcut_from_position`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, ClassVar

import numpy as np
from pydantic import Field

from planners.api import Observation, Plan, Planner, PlannerConfig, PlannerContext
from planners.give_up import GiveUpTracker
from planners.search import BoolGrid, CompiledAccept, DistanceField, IndexArray, shortcut
from planners.viewpoints import ViewpointCandidates, ring_offsets
from planners.waypoints import (
    escape_starts,
    nearest_traversable,
    path_waypoints,
    shortcut_from_position,
)

# Pockets of traversable space an escaping vehicle tries before the exploration ends: each
# failed search floods its whole pocket.
_MAX_POCKETS = 4


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
    # v2: a viewpoint must see into the unknown beside its frontier voxel, not the voxel alone
    # (`planners.viewpoints.sees_into_unknown`): the robot goes to a frontier to sense what lies
    # beyond it. Forced by the map: a floor voxel that grazing rays left free over the unknown
    # interior of the slab is a frontier no view clears (half of OFFICES B's frontier voxels),
    # and v1 spent most of its flight looking at them from 0.65 m up. False (v1): a clear line
    # of sight to the frontier voxel suffices.
    view_into_unknown: bool = False
    # v2: Yamauchi's robot marks the frontier it reached as visited once it has sensed all
    # around; a level camera with a 90 degree view senses what it looks at, so every frontier
    # voxel in view within this distance of a reached viewpoint, with a clear line of sight
    # into its unknown side, counts as visited (given up after `give_up_after` such arrivals).
    # The distance is the farthest viewpoint distance: there the 80 x 60 rays fused per frame
    # are still under a voxel apart. None (v1): the target alone counts.
    visited_view_reach_m: float | None = Field(None, gt=0.0)
    # v2, forced by the framework: the traversable mask keeps the safety radius from unknown and
    # occupied voxels, so a newly seen obstacle can leave the vehicle outside it (a desk edge
    # 0.4 m away), where Yamauchi's point robot on its grid never stands. The framework lets the
    # first leg leave through known free voxels: the search starts from the traversable voxels
    # within this many voxels that such a leg reaches, nearest first, trying the next pocket
    # when one leads to no viewpoint. None (v1): the nearest traversable voxel within 3, or the
    # end of the exploration.
    escape_reach_voxels: int | None = Field(None, ge=1)
    # v3: Yamauchi's robot follows its path from where it stands. The vehicle comes to rest
    # within millimetres of a waypoint, not on the voxel centre the search starts from; where
    # the straight leg from its exact position to the path's next vertex leaves the traversable
    # voxels, v1 and v2 fly back to that centre first and ask again there (every waypoint), which
    # in a map that no longer changes repeats for ever (`docs/planners/classic.md`). True: the
    # path is shortcut from the exact position instead
    # (`planners.waypoints.shortcut_from_position`). False (v1, v2): from the voxel's centre.
    shortcut_from_position: bool = False


class ClassicV2Config(ClassicConfig):
    """classic-v2: viewpoints see into the unknown, visited frontiers are what the camera looked
    into, and the vehicle escapes where the map closed in around it (see the fields'
    comments)."""

    view_into_unknown: bool = True
    visited_view_reach_m: float | None = Field(3.5, gt=0.0)
    escape_reach_voxels: int | None = Field(10, ge=1)


class ClassicV3Config(ClassicV2Config):
    """classic-v3: as classic-v2, with the path shortcut from the vehicle's exact position, so
    that it does not fly back to its voxel's centre (see the field's comment)."""

    shortcut_from_position: bool = True


class ClassicPlanner(Planner):
    """The code of every Classic version; `config_model` picks the version, and a planner
    falling back to Classic passes the config of the version it wants."""

    config_model: ClassVar[type[ClassicConfig]] = ClassicConfig
    config: ClassicConfig

    def reset(self, ctx: PlannerContext) -> None:
        super().reset(ctx)
        cfg = self.config
        self._offsets = ring_offsets(
            cfg.view_distances_m, cfg.view_height_offsets_m, cfg.view_directions
        )
        self._give_up = GiveUpTracker(cfg.give_up_after, cfg.give_up_radius_voxels,
                                      camera=ctx.camera, view_reach_m=cfg.visited_view_reach_m)
        self._goal: IndexArray | None = None
        self._target: IndexArray | None = None

    def plan(self, obs: Observation) -> Plan:
        cfg, view = self.config, obs.map
        here = view.world_to_index(obs.pose.position[None])[0]
        given_up = self._give_up.update(here, self._goal, self._target, obs)
        clusters = view.frontier_clusters(cfg.min_cluster_size)
        if not clusters:
            return Plan.finished("no frontier left")
        if cfg.escape_reach_voxels is None:
            start = nearest_traversable(view.traversable, here)
            starts = np.zeros((0, 3), dtype=np.int64) if start is None else start[None]
        else:
            starts = escape_starts(view, obs.pose.position, cfg.escape_reach_voxels)
        if len(starts) == 0:
            return Plan.finished("the vehicle is not in traversable space")
        candidates = ViewpointCandidates(
            view,
            clusters,
            self._offsets,
            samples_per_cluster=cfg.samples_per_cluster,
            max_elevation_rad=np.radians(cfg.max_view_elevation_deg),
            max_range_m=self.context.camera.max_range_m,
            excluded=given_up,
            into_unknown=cfg.view_into_unknown,
        )
        # The search tests a candidate's line of sight when it reaches the candidate's voxel:
        # the nearest viewpoint is the same as with every candidate tested first, at a fraction
        # of the tests on large maps.
        field = (self._search(view.traversable, starts, view.voxel_size, candidates.eyes,
                              candidates) if len(candidates) else None)
        goal = None if field is None else field.nearest_goal
        if field is None or goal is None:
            if len(candidates.all()) == 0:
                return Plan.finished("no frontier can be seen from traversable space")
            return Plan.finished("no frontier viewpoint is reachable")
        self._goal, self._target = goal, candidates.target_at(goal)
        found = field.path_to(goal)
        path = (shortcut_from_position(view, found, obs.pose.position)
                if cfg.shortcut_from_position else shortcut(found, view.traversable))
        target_world = view.index_to_world(self._target[None])[0]
        waypoints = path_waypoints(view, path, obs.pose.position, target_world)
        return Plan(
            waypoints,
            horizon_s=0.0,
            info={"clusters": len(clusters), "path_m": field.distance_to(goal)},
        )

    @staticmethod
    def _search(traversable: BoolGrid, starts: IndexArray, voxel_size: float,
                goals: BoolGrid,
                accept: Callable[[IndexArray], bool] | CompiledAccept | None = None,
                ) -> DistanceField | None:
        """The search from the first of `starts` that reaches a goal, skipping starts a failed
        search already reached (the same pocket), at most `_MAX_POCKETS` searches; None when
        none does."""
        failed: list[DistanceField] = []
        for start in starts:
            if any(np.isfinite(f.distance_to(start)) for f in failed):
                continue
            field = DistanceField(traversable, start, voxel_size, goals=goals, accept=accept)
            if field.nearest_goal is not None or len(starts) == 1:
                return field
            failed.append(field)
            if len(failed) == _MAX_POCKETS:
                break
        return None


class Classic(ClassicPlanner):
    """classic-v1."""

    config_model = ClassicConfig
    config: ClassicConfig


class ClassicV2(ClassicPlanner):
    """classic-v2."""

    config_model = ClassicV2Config
    config: ClassicV2Config


class ClassicV3(ClassicPlanner):
    """classic-v3."""

    config_model = ClassicV3Config
    config: ClassicV3Config


def frontier_fallback(fallback: ClassicPlanner, obs: Observation, **info: Any) -> Plan:
    """Classic's nearest frontier as another planner's fallback: Classic's plan, marked
    `mode: classic` with `info` added, or Classic's own end of the exploration."""
    plan = fallback.plan(obs)
    if plan.done:
        return plan
    merged = {**plan.info, "mode": "classic", **info}
    return Plan(plan.waypoints, horizon_s=plan.horizon_s, info=merged)
