"""FUEL (Zhou, Zhang, Chen, Shen, RA-L 2021): fast UAV exploration by an incremental frontier
information structure and hierarchical planning.

Every call (`planExploreMotion` of the public code's `fast_exploration_manager.cpp`):

1. The frontier information structure (`planners.fuel_frontier`): clusters split to a bounded
   size, each with viewpoints on circles around it ranked by coverage. Viewpoints of a cluster
   whose voxels did not change are kept from the previous call (FUEL's incremental update),
   those no longer traversable dropped; in v2 a cluster without viewpoints samples them again.
2. The global tour: an asymmetric TSP over the vehicle and each cluster's best viewpoint (the
   first one `min_candidate_dist` away), costed by `planners.fuel_costs.pose_cost`, returning to
   the start for free (column 0 is zero), solved by `planners.tour` (LKH in FUEL).
3. Local refinement: over the first clusters of the tour (up to `refined_num`, stopping after
   one beyond `refined_radius` once two are in), the sequence of their top viewpoints (at most
   `top_view_num`, coverage above `max_decay` of the best) of least total cost, by dynamic
   programming over the layers (FUEL's Dijkstra on this layered graph); the last cluster
   contributes its best viewpoint only.
4. The flight: a shortest grid path (`planners.astar`) to the first refined viewpoint, cut at
   `radius_far_m` of path as FUEL cuts far goals, the last waypoint yawed to the viewpoint's
   yaw. While flying, the planner is asked every `covered_check_s`: it replans after
   `replan_period_s` of flight, or earlier once a cluster it planned with lost at least
   `min_view_finish_fraction` of its voxels (FUEL's `fsm/thresh_replan*` triggers).

Cost between poses (FUEL's `ViewNode::computeCost`): max(path length / v_max + w_dir x angle
between the current velocity and the straight line to the goal, yaw change / yaw rate). Path
lengths: the straight line when it stays in traversable space, otherwise the shortest path on
a coarse grid of `path_cell_m` cells (FUEL searches A* at 0.4 m).

The exploration ends when no cluster has a viewpoint, or, at rest, when none can be reached.
"""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np
import numpy.typing as npt
from pydantic import Field

from planners.api import Observation, Plan, Planner, PlannerConfig, PlannerContext, PlanOutcome
from planners.astar import PathCache
from planners.fuel_costs import PathLengths, pose_cost
from planners.fuel_frontier import Cluster, Viewpoints, clusters, sample_offsets, sample_viewpoints
from planners.give_up import GiveUpTracker
from planners.search import BoolGrid, IndexArray, shortcut
from planners.tour import solve_atsp
from planners.waypoints import escape_starts, path_waypoints
from sim.map_view import MapView
from sim.occupancy import VoxelState

FloatArray = npt.NDArray[np.float64]


class FuelConfig(PlannerConfig):
    """FUEL's settings; sources in `docs/planners.md` (the public code's `algorithm.xml` unless
    marked ours)."""

    cluster_min: int = Field(100, ge=0)
    cluster_size_xy_m: float = Field(2.0, gt=0.0)
    min_frontier_height_m: float | None = Field(0.4, ge=0.0)
    down_sample: int = Field(3, ge=1)
    candidate_rmin_m: float = Field(1.5, gt=0.0)
    candidate_rmax_m: float = Field(2.5, gt=0.0)
    candidate_rnum: int = Field(3, ge=0)
    candidate_dphi_deg: float = Field(15.0, gt=0.0, le=180.0)
    min_visib_num: int = Field(15, ge=0)
    min_candidate_dist_m: float = Field(0.75, ge=0.0)
    refine_local: bool = True
    refined_num: int = Field(7, ge=1)
    refined_radius_m: float = Field(5.0, gt=0.0)
    top_view_num: int = Field(15, ge=1)
    max_decay: float = Field(0.8, ge=0.0, le=1.0)
    v_max: float | None = Field(None, gt=0.0)  # None: the vehicle's
    yaw_rate_deg_s: float = Field(60.0, gt=0.0)
    w_dir: float = Field(1.5, ge=0.0)
    unreachable_m: float = Field(1000.0, gt=0.0)
    path_cell_m: float = Field(0.4, gt=0.0)
    radius_far_m: float | None = Field(5.0, gt=0.0)
    replan_in_flight: bool = True
    replan_period_s: float = Field(1.5, gt=0.0)
    covered_check_s: float = Field(0.5, gt=0.0)
    min_view_finish_fraction: float = Field(0.2, gt=0.0, le=1.0)
    exact_max_nodes: int = Field(12, ge=0, le=16)
    give_up_after: int = Field(2, ge=1)
    give_up_radius_voxels: int = Field(2, ge=0)
    visited_view_reach_m: float | None = Field(3.5, gt=0.0)
    escape_reach_voxels: int = Field(10, ge=1)
    # v2: a cluster without viewpoints (dormant) samples them again at every call, since the
    # map around it may have opened up; v1 keeps it dormant until its voxels change, as FUEL's
    # code does, where the framework's clearance (`docs/planners/fuel.md`) leaves more dormant.
    resample_dormant: bool = False


class FuelV2Config(FuelConfig):
    """fuel-v2: dormant clusters sample their viewpoints again at every call."""

    resample_dormant: bool = True


class FuelPlanner(Planner):
    """The code of every FUEL version; `config_model` picks the version."""

    config_model: ClassVar[type[FuelConfig]] = FuelConfig
    config: FuelConfig

    def reset(self, ctx: PlannerContext) -> None:
        super().reset(ctx)
        cfg = self.config
        self._offsets = sample_offsets(cfg.candidate_rmin_m, cfg.candidate_rmax_m,
                                       cfg.candidate_rnum, math.radians(cfg.candidate_dphi_deg))
        self._paths = PathCache()
        self._coarse_paths = PathCache(max_entries=8192)
        self._give_up = GiveUpTracker(cfg.give_up_after, cfg.give_up_radius_voxels,
                                      camera=ctx.camera, view_reach_m=cfg.visited_view_reach_m)
        self._views: dict[bytes, Viewpoints] = {}
        self._groups: dict[bytes, list[Cluster]] = {}
        self._goal: IndexArray | None = None
        self._target: IndexArray | None = None
        self._planned_at = 0.0
        self._planned: list[IndexArray] = []

    @property
    def _v_max(self) -> float:
        return self.config.v_max if self.config.v_max is not None else self.context.limits.v_max

    def plan(self, obs: Observation) -> Plan:
        cfg = self.config
        if obs.last_outcome == PlanOutcome.FLYING and not self._replan_due(obs):
            return Plan.keep_flying(cfg.covered_check_s)
        view = obs.map
        here = view.world_to_index(np.asarray(obs.pose.position)[None])[0]
        given_up = self._give_up.update(here, self._goal, self._target, obs)
        self._goal = self._target = None
        found = self._structure(view, given_up)
        if not found:
            return Plan.finished("no coverable frontier")
        starts = escape_starts(view, obs.pose.position, cfg.escape_reach_voxels)
        if len(starts) == 0:
            return self._stuck(obs, "the vehicle is not in traversable space")
        start_voxel = starts[0]
        pos = np.asarray(obs.pose.position, dtype=np.float64)
        lengths = PathLengths(view, cfg.path_cell_m, self._coarse_paths)
        start_m = view.index_to_world(start_voxel[None])[0]
        everywhere = lengths.reachable(start_m, np.vstack([v.positions for _, v in found]))
        active: list[tuple[Cluster, Viewpoints]] = []
        offset = 0
        for cluster, views in found:
            ok = everywhere[offset:offset + len(views)]
            offset += len(views)
            if ok.any():
                active.append((cluster, views.take(ok)))
        self._planned = [c.voxels for c, _ in found]
        self._planned_at = obs.time
        if not active:
            return self._stuck(obs, "no frontier viewpoint is reachable")
        order = self._global_tour(obs, lengths, active)
        candidates = self._refine(obs, lengths, active, order)
        for position, yaw, which in candidates:
            plan = self._flight(obs, start_voxel, pos, position, yaw)
            if plan is not None:
                cluster = active[which][0]
                near = np.argmin(np.sum((view.index_to_world(cluster.voxels)
                                         - cluster.average) ** 2, axis=1))
                self._target = cluster.voxels[near]
                plan.info.update({"clusters": len(found), "active": len(active),
                                  "tour": len(order)})
                return plan
        return self._stuck(obs, "no path to any viewpoint")

    def _stuck(self, obs: Observation, why: str) -> Plan:
        """In flight, keep flying and decide again at rest (the moving vehicle may be between
        voxels the search can start from); at rest, the end of the exploration."""
        if obs.last_outcome == PlanOutcome.FLYING:
            return Plan.keep_flying(self.config.covered_check_s, info={"why": why})
        return Plan.finished(why)

    def _replan_due(self, obs: Observation) -> bool:
        """FUEL's in-flight triggers: the replanning period is over, or a cluster planned with
        lost `min_view_finish_fraction` of its frontier voxels."""
        cfg = self.config
        if obs.time - self._planned_at >= cfg.replan_period_s:
            return True
        frontier = obs.map.frontier
        for voxels in self._planned:
            gone = ~frontier[voxels[:, 0], voxels[:, 1], voxels[:, 2]]
            if np.count_nonzero(gone) >= cfg.min_view_finish_fraction * len(voxels):
                return True
        return False

    def _structure(self, view: MapView, given_up: BoolGrid) -> list[tuple[Cluster, Viewpoints]]:
        """Clusters with at least one viewpoint; an unchanged cluster's viewpoints are reused
        (those still traversable; with `resample_dormant`, sampled again while there are none)."""
        cfg, ctx = self.config, self.context
        min_z = (None if cfg.min_frontier_height_m is None
                 else float(ctx.bounds_min[2]) + cfg.min_frontier_height_m)
        found = clusters(view, cfg.cluster_min, cfg.cluster_size_xy_m, cfg.down_sample,
                         excluded=given_up, min_z_m=min_z, cache=self._groups)
        opaque = view.state != VoxelState.FREE
        kept: dict[bytes, Viewpoints] = {}
        out: list[tuple[Cluster, Viewpoints]] = []
        for cluster in found:
            key = cluster.voxels.tobytes()
            views = self._views.get(key)
            if views is not None and len(views):
                idx = view.world_to_index(views.positions)
                views = views.take(view.traversable[idx[:, 0], idx[:, 1], idx[:, 2]])
            if views is None or (len(views) == 0 and cfg.resample_dormant):
                views = sample_viewpoints(view, cluster, self._offsets, opaque, ctx.camera,
                                          cfg.min_visib_num)
            kept[key] = views
            if len(views):
                out.append((cluster, views))
        self._views = kept
        return out

    def _costs(self, lengths: PathLengths, a: FloatArray, b: FloatArray, ya: FloatArray,
               yb: FloatArray, velocity: FloatArray) -> FloatArray:
        """(N, M) FUEL's costs from the poses (a (N, 3), ya (N,)) to (b (M, 3), yb (M,))."""
        cfg = self.config
        length = lengths.matrix(a, b)
        length[~np.isfinite(length)] = cfg.unreachable_m
        return pose_cost(length, a[:, None, :], b[None, :, :], ya[:, None], yb[None, :],
                         velocity, self._v_max, math.radians(cfg.yaw_rate_deg_s), cfg.w_dir)

    def _top(self, pos: FloatArray, views: Viewpoints) -> int:
        """FUEL's cluster representative: the best-covering viewpoint at least
        `min_candidate_dist_m` away, else the best."""
        far = np.linalg.norm(views.positions - pos, axis=1) >= self.config.min_candidate_dist_m
        return int(np.argmax(far)) if far.any() else 0

    def _global_tour(self, obs: Observation, lengths: PathLengths,
                     active: list[tuple[Cluster, Viewpoints]]) -> list[int]:
        """Cluster indices in the order of the global tour."""
        if len(active) == 1:
            return [0]
        pos = np.asarray(obs.pose.position, dtype=np.float64)
        vel = np.asarray(obs.velocity, dtype=np.float64)
        top = [self._top(pos, v) for _, v in active]
        points = np.array([v.positions[t] for (_, v), t in zip(active, top, strict=True)])
        yaws = np.array([v.yaws[t] for (_, v), t in zip(active, top, strict=True)])
        n = len(active) + 1
        cost = np.zeros((n, n))
        cost[0, 1:] = self._costs(lengths, pos[None], points, np.array([obs.pose.yaw]), yaws,
                                  vel)[0]
        cost[1:, 1:] = self._costs(lengths, points, points, yaws, yaws, np.zeros(3))
        np.fill_diagonal(cost, 0.0)
        tour = solve_atsp(cost, exact_max_nodes=self.config.exact_max_nodes)
        return [int(t) - 1 for t in tour[1:]]

    def _refine(self, obs: Observation, lengths: PathLengths,
                active: list[tuple[Cluster, Viewpoints]],
                order: list[int]) -> list[tuple[FloatArray, float, int]]:
        """Candidate next viewpoints, best first: the refined one, then the other top views of
        the first cluster by cost, then the representatives of the later clusters of the tour
        (fallbacks when the grid path to the best fails)."""
        cfg = self.config
        pos = np.asarray(obs.pose.position, dtype=np.float64)
        vel = np.asarray(obs.velocity, dtype=np.float64)
        if not cfg.refine_local:
            out = []
            for c in order:
                views = active[c][1]
                t = self._top(pos, views)
                out.append((views.positions[t], float(views.yaws[t]), c))
            return out
        ids: list[int] = []
        for c in order[:cfg.refined_num]:
            ids.append(c)
            views = active[c][1]
            top = views.positions[self._top(pos, views)]
            if np.linalg.norm(top - pos) > cfg.refined_radius_m and len(ids) >= 2:
                break
        layers = [self._top_views(pos, active[c][1]) for c in ids]
        if len(layers) > 1:
            layers[-1] = layers[-1][:1]
        # Dynamic programming over the layers: best[k] is the least cost of reaching the k-th
        # node of the current layer from the vehicle, first[k] the first-layer node it came by.
        here_yaw = np.array([obs.pose.yaw])
        points = [np.array([p for p, _ in layer]) for layer in layers]
        yaws = [np.array([y for _, y in layer]) for layer in layers]
        direct = self._costs(lengths, pos[None], points[0], here_yaw, yaws[0], vel)[0]
        best, first = direct, np.arange(len(points[0]))
        for k in range(1, len(layers)):
            step = self._costs(lengths, points[k - 1], points[k], yaws[k - 1], yaws[k],
                               np.zeros(3))
            total = best[:, None] + step
            arg = np.argmin(total, axis=0)
            best = total[arg, np.arange(len(points[k]))]
            first = first[arg]
        chosen = int(first[int(np.argmin(best))])
        first_layer = layers[0]
        c0 = ids[0]
        out = [(first_layer[chosen][0], first_layer[chosen][1], c0)]
        out += [(first_layer[k][0], first_layer[k][1], c0)
                for k in np.argsort(direct, kind="stable") if k != chosen]
        for c in order[1:]:
            views = active[c][1]
            t = self._top(pos, views)
            out.append((views.positions[t], float(views.yaws[t]), c))
        return out

    def _top_views(self, pos: FloatArray, views: Viewpoints) -> list[tuple[FloatArray, float]]:
        """FUEL's `getViewpointsInfo`: up to `top_view_num` viewpoints covering more than
        `max_decay` of the best, at least `min_candidate_dist_m` away unless none is."""
        cfg = self.config
        thresh = int(views.visible[0] * cfg.max_decay)
        good = np.flatnonzero(views.visible > thresh)
        # The best one always qualifies (visible > int(visible * decay) for decay < 1).
        if len(good) == 0:
            good = np.array([0])
        far = good[np.linalg.norm(views.positions[good] - pos, axis=1) >= cfg.min_candidate_dist_m]
        pick = (far if len(far) else good)[:cfg.top_view_num]
        return [(views.positions[k], float(views.yaws[k])) for k in pick]

    def _flight(self, obs: Observation, start: IndexArray, pos: FloatArray, goal: FloatArray,
                yaw: float) -> Plan | None:
        """Waypoints of the grid path to the viewpoint, cut at `radius_far_m`, the last one
        yawed to the viewpoint's yaw; None when the grid path does not exist."""
        cfg, view = self.config, obs.map
        goal_voxel = view.world_to_index(goal[None])[0]
        if np.array_equal(goal_voxel, start):
            path = start[None]
        else:
            path, _ = self._paths.path(view.traversable, start, goal_voxel, view.voxel_size)
            if len(path) == 0:
                return None
            path = shortcut(path, view.traversable)
        truncated = False
        if cfg.radius_far_m is not None and len(path) > 1:
            pts = view.index_to_world(path)
            run = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
            if run[-1] > cfg.radius_far_m:
                # FUEL keeps the first path point at or beyond the radius.
                last = int(np.searchsorted(run, cfg.radius_far_m))
                path, truncated = path[:last + 1], True
        look = pos + np.array([math.cos(yaw), math.sin(yaw), 0.0])
        waypoints = path_waypoints(view, path, pos, look)
        waypoints[-1, 3] = yaw
        if not truncated:
            self._goal = path[-1]
        info: dict[str, int | float | str] = {"truncated": int(truncated), "yaw": yaw}
        replan = cfg.covered_check_s if cfg.replan_in_flight else None
        return Plan(waypoints, horizon_s=None, replan_s=replan, info=info)


class Fuel(FuelPlanner):
    """fuel-v1."""

    config_model = FuelConfig
    config: FuelConfig


class FuelV2(FuelPlanner):
    """fuel-v2."""

    config_model = FuelV2Config
    config: FuelV2Config
