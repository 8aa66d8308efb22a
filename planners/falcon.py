"""FALCON (Zhang, Chen, Feng, Zhou, Shen, T-RO 2024): fast autonomous aerial exploration using
coverage path guidance.

Every call (`planExploreMotionHGrid` of the public code's `exploration_manager.cpp`), on FUEL's
frontier structure (`planners.fuel`, whose clusters, viewpoints, replanning triggers and flight
this planner shares):

1. The space decomposition (`planners.falcon_zones`): cells, their free and unknown zones and
   the connectivity graph between them.
2. The coverage path (`planners.falcon_guidance`): an ATSP over the zones holding frontier
   viewpoints and the unknown zones, the global guidance.
3. The local ordering: a sequential ordering problem (`planners.falcon_sop`) over the
   frontiers of the coverage path's first zone and of the vehicle's cell, keeping the coverage
   path's order; the frontiers it visits before the coverage path's next zone are the local
   tour.
4. The refinement: over the local tour's first clusters (FUEL's `refined_num`,
   `refined_radius`), the sequence of their top viewpoints of least cost that ends at the
   coverage path's next zone, by dynamic programming over the layers (the code's Dijkstra on
   this layered graph); its first viewpoint is the next goal, flown as FUEL flies it.

Costs are FALCON's time lower bound (`planners.falcon_costs`).
"""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np
import numpy.typing as npt
from pydantic import Field

from planners.api import Observation, PlannerContext
from planners.falcon_costs import Dynamics, time_cost
from planners.falcon_guidance import CoveragePath, coverage_path, lengths
from planners.falcon_sop import MAX_FRONTIERS, solve_sop
from planners.falcon_zones import ZoneGrid, Zones
from planners.fuel import FuelConfig, FuelPlanner
from planners.fuel_costs import PathLengths
from planners.fuel_frontier import Cluster, Viewpoints
from planners.search import IndexArray
from sim.occupancy import VoxelState

FloatArray = npt.NDArray[np.float64]
Active = list[tuple[Cluster, Viewpoints]]


class FalconConfig(FuelConfig):
    """FALCON's settings; sources in `docs/planners/falcon.md` (the public code's
    `frontier_finder.yaml`, `hgrid.yaml`, `exploration_manager.yaml` unless marked ours). The
    frontier structure's other settings are FUEL's, which FALCON's code keeps."""

    cluster_size_xy_m: float = Field(2.5, gt=0.0)  # frontier_finder/cluster_size_xy
    min_frontier_height_m: float | None = Field(0.1, ge=0.0)  # ground_height + ground_offset
    min_candidate_dist_m: float = Field(0.5, ge=0.0)  # frontier_finder/min_candidate_dist
    min_view_finish_fraction: float = Field(0.25, gt=0.0, le=1.0)  # frontier_finder/...
    replan_period_s: float = Field(3.0, gt=0.0)  # fsm/replan_thresh3
    covered_check_s: float = Field(0.2, gt=0.0)  # fsm/replan_thresh2
    yaw_rate_deg_s: float = Field(57.3, gt=0.0)  # the vehicle's (uav_model's max_yaw_velocity)
    yaw_acc_deg_s2: float = Field(114.6, gt=0.0)  # the vehicle's (max_yaw_acceleration)
    a_max: float | None = Field(None, gt=0.0)  # None: the vehicle's (max_linear_acceleration)
    vz_max: float = Field(1.0, gt=0.0)  # computePathCost's "max z velocity"
    cell_size_m: float = Field(5.0, gt=0.0)  # hgrid/cell_size_max
    grid_layers: int | None = Field(None, ge=1)  # None: by the area's height, as the code
    ccl_step: int = Field(2, ge=1)  # hgrid/ccl_step
    min_free_cells: int = Field(10, ge=1)  # getCCLCenters: zones of fewer samples dropped
    min_unknown_fraction: float = Field(0.1, ge=0.0, le=1.0)  # hgrid/min_unknown_num_scale
    hybrid_search_radius_m: float = Field(15.0, gt=0.0)  # exploration_manager/hybrid_search_...
    unknown_penalty: float = Field(2.0, ge=1.0)  # exploration_manager/unknown_penalty_factor
    sop_max_frontiers: int = Field(10, ge=1, le=MAX_FRONTIERS)  # ours: the exact SOP's size


class FalconV2Config(FalconConfig):
    """falcon-v2: dormant clusters sample their viewpoints again at every call (as fuel-v2)."""

    resample_dormant: bool = True


class FalconPlanner(FuelPlanner):
    """The code of every FALCON version; `config_model` picks the version. FUEL's `plan` runs
    with FALCON's global tour (coverage path and ordering) and refinement."""

    config_model: ClassVar[type[FalconConfig]] = FalconConfig
    config: FalconConfig

    def reset(self, ctx: PlannerContext) -> None:
        super().reset(ctx)
        self._grid: ZoneGrid | None = None
        self._guide: FloatArray | None = None
        self._local = 0

    def _dynamics(self) -> Dynamics:
        cfg, limits = self.config, self.context.limits
        return Dynamics(self._v_max, cfg.a_max if cfg.a_max is not None else limits.a_max,
                        cfg.vz_max, math.radians(cfg.yaw_rate_deg_s),
                        math.radians(cfg.yaw_acc_deg_s2))

    def _zones(self, obs: Observation) -> Zones:
        view, cfg = obs.map, self.config
        if self._grid is None:
            self._grid = ZoneGrid(view.shape, view.origin, view.voxel_size, cfg.cell_size_m,
                                  cfg.ccl_step, cfg.min_free_cells, cfg.min_unknown_fraction,
                                  self.context.safety_radius_m, cfg.grid_layers)
        return self._grid.update(view)

    def _global_tour(self, obs: Observation, lengths_: PathLengths, active: Active) -> list[int]:
        """Active clusters in the order to visit: the local tour first (its length kept for
        `_refine`), then the others by cost from the vehicle as fallbacks."""
        cfg, view = self.config, obs.map
        pos = np.asarray(obs.pose.position, dtype=np.float64)
        vel = np.asarray(obs.velocity, dtype=np.float64)
        top = [self._top(pos, v) for _, v in active]
        tops = np.array([v.positions[t] for (_, v), t in zip(active, top, strict=True)])
        yaws = np.array([v.yaws[t] for (_, v), t in zip(active, top, strict=True)])
        zones = self._zones(obs)
        assert self._grid is not None
        zone = self._free_zone(obs, zones, tops)
        dyn = self._dynamics()
        direct = time_cost(self._lengths(lengths_, pos[None], tops)[0], pos, tops, obs.pose.yaw,
                           yaws, vel, dyn)
        by_cost = [int(i) for i in np.argsort(direct, kind="stable")]
        self._guide, self._local = None, 0
        ids = np.unique(zone[zone >= 0])
        if len(ids) == 0:
            return by_cost
        nodes = np.array([self._node(tops[zone == z]) for z in ids])
        passable = view.state != VoxelState.OCCUPIED
        path = coverage_path(view, zones, passable, pos, vel, nodes, ids, dyn,
                             cfg.hybrid_search_radius_m, cfg.unknown_penalty, cfg.exact_max_nodes)
        cells = self._grid.cell_of(view, np.vstack([pos, tops, path.positions[:1]]))
        near = cells[1:-1] == cells[-1] if path.unknown[0] else zone == path.zone[0]
        local = np.flatnonzero(near | (cells[1:-1] == cells[0]))
        local = local[np.argsort(direct[local], kind="stable")][:cfg.sop_max_frontiers]
        prefix = self._order(obs, lengths_, zones, passable, path, local, tops, yaws, zone,
                             direct, dyn)
        if not prefix:
            # Every local frontier comes after the next zone: its own frontiers, nearest first.
            prefix = [i for i in by_cost if zone[i] == path.zone[0]][:1]
        self._local = len(prefix)
        return prefix + [i for i in by_cost if i not in prefix]

    def _free_zone(self, obs: Observation, zones: Zones, tops: FloatArray) -> IndexArray:
        """(A,) the free zone each top viewpoint stands in, else the nearest free zone of its
        cell, else -1."""
        assert self._grid is not None
        zone = zones.zone_at(obs.map, tops)
        cells = self._grid.cell_of(obs.map, tops)
        for i in np.flatnonzero((zone < 0) | zones.unknown[np.maximum(zone, 0)]):
            same = np.flatnonzero((zones.cell == cells[i]) & ~zones.unknown)
            if len(same) == 0:
                zone[i] = -1
                continue
            d = np.linalg.norm(zones.centers[same] - tops[i], axis=1)
            zone[i] = same[int(np.argmin(d))]
        return zone

    @staticmethod
    def _node(points: FloatArray) -> FloatArray:
        """An active zone's place on the coverage path: its viewpoint nearest their mean."""
        d = np.linalg.norm(points - points.mean(axis=0), axis=1)
        out: FloatArray = points[int(np.argmin(d))]
        return out

    def _lengths(self, lengths_: PathLengths, a: FloatArray, b: FloatArray) -> FloatArray:
        out = lengths_.matrix(a, b)
        out[~np.isfinite(out)] = self.config.unreachable_m
        return out

    def _order(self, obs: Observation, lengths_: PathLengths, zones: Zones,
               passable: npt.NDArray[np.bool_], path: CoveragePath, local: IndexArray,
               tops: FloatArray, yaws: FloatArray, zone: IndexArray, direct: FloatArray,
               dyn: Dynamics) -> list[int]:
        """The local frontiers visited before the coverage path's next zone, by the SOP; the
        position of that zone kept for the refinement."""
        if len(local) == 0:
            return []
        cfg, view = self.config, obs.map
        rest = slice(1, None)  # the first zone is represented by its frontiers
        zp, zz = path.positions[rest], path.zone[rest]
        f, fy = tops[local], yaws[local]
        between = time_cost(self._lengths(lengths_, f, f), f[:, None], f[None], fy[:, None],
                            fy[None], np.zeros(3), dyn)
        to_zone = time_cost(lengths(view, zones, passable, f, zone[local], zp, zz,
                                    cfg.hybrid_search_radius_m),
                            f[:, None], zp[None], 0.0, 0.0, np.zeros(3), dyn)
        to_zone[:, path.unknown[rest]] *= cfg.unknown_penalty
        start_zone = path.legs_s[0] + path.legs_s[1] if len(zp) else 0.0
        order = solve_sop(np.concatenate([direct[local], [start_zone]]), between, to_zone,
                          to_zone.T, path.legs_s[2:])
        prefix: list[int] = []
        for node in order:
            if node >= len(local):
                self._guide = zp[node - len(local)]
                break
            prefix.append(int(local[node]))
        return prefix

    def _refine(self, obs: Observation, lengths_: PathLengths, active: Active,
                order: list[int]) -> list[tuple[FloatArray, float, int]]:
        """Candidate next viewpoints, best first: the first of the least-cost sequence of top
        viewpoints over the local tour's clusters ending at the coverage path's next zone, then
        the first cluster's other top viewpoints by cost, then the other clusters' best."""
        cfg = self.config
        pos = np.asarray(obs.pose.position, dtype=np.float64)
        vel = np.asarray(obs.velocity, dtype=np.float64)
        dyn = self._dynamics()
        chosen: list[int] = []
        for c in order[:max(1, min(self._local, cfg.refined_num))]:
            chosen.append(c)
            t = self._top(pos, active[c][1])
            if np.linalg.norm(active[c][1].positions[t] - pos) > cfg.refined_radius_m \
                    and len(chosen) >= 2:
                break
        layers = [self._top_views(pos, active[c][1]) for c in chosen]
        pts = [np.array([p for p, _ in layer]) for layer in layers]
        yws = [np.array([y for _, y in layer]) for layer in layers]
        first = time_cost(self._lengths(lengths_, pos[None], pts[0])[0], pos, pts[0],
                          obs.pose.yaw, yws[0], vel, dyn)
        steps = [time_cost(self._lengths(lengths_, pts[k - 1], pts[k]), pts[k - 1][:, None],
                           pts[k][None], yws[k - 1][:, None], yws[k][None], np.zeros(3), dyn)
                 for k in range(1, len(layers))]
        end = None
        if cfg.refine_local and self._guide is not None:
            gap = np.linalg.norm(pts[-1] - self._guide, axis=1)
            end = time_cost(gap, pts[-1], self._guide, yws[-1], yws[-1], np.zeros(3), dyn)
        best = _first_of_cheapest(first, steps if cfg.refine_local else [], end)
        ranked = [best] + [int(k) for k in np.argsort(first, kind="stable") if k != best]
        head = [(pts[0][k], float(yws[0][k]), chosen[0]) for k in ranked]
        return head + self._best_of(pos, active, order[1:])

    def _best_of(self, pos: FloatArray, active: Active,
                 clusters: list[int]) -> list[tuple[FloatArray, float, int]]:
        """Each cluster's representative viewpoint (FUEL's `_top`) as a flight candidate."""
        return [(v.positions[k], float(v.yaws[k]), c) for c in clusters
                for v in (active[c][1],) for k in (self._top(pos, v),)]


def _first_of_cheapest(first: FloatArray, steps: list[FloatArray],
                       end: FloatArray | None) -> int:
    """The first-layer node of the least-cost path through layered nodes: `first` (n0,) from the
    start, `steps[k]` (n_k, n_k+1) between layers, `end` (n_last,) to a final node."""
    total = first.copy()
    origin = np.arange(len(first))
    for step in steps:
        through = total[:, None] + step
        pick = np.argmin(through, axis=0)
        total = through[pick, np.arange(step.shape[1])]
        origin = origin[pick]
    if end is not None:
        total = total + end
    return int(origin[int(np.argmin(total))])


class Falcon(FalconPlanner):
    """falcon-v1."""

    config_model = FalconConfig
    config: FalconConfig


class FalconV2(FalconPlanner):
    """falcon-v2."""

    config_model = FalconV2Config
    config: FalconV2Config
