"""SplatPlanner (Brunel, Bourki, Demonceaux, Strauss, ICRA 2021): frontier viewpoints scored by
a permutohedral Gaussian filter of the frontier.

Every frontier voxel, with its position and its normal (pointing into the unknown), is splatted
onto a 6D permutohedral lattice (`planners.permutohedral`) with features
(position / sigma_p, normal / sigma_n); the lattice's Gaussian filter then gives any query
(a point looked at, a viewing direction) the density of frontier around that point facing that
way. For speed, floor- and ceiling-facing voxels are left out (no level view weighs them much),
voxels of one small cell and normal are splatted together, and the lattice is kept between
calls, splatting only what changed.

Candidate viewpoints stand at the sensing distance behind frontier voxels (against their
normal, level, facing them) in traversable space; each one's gain is the filtered density at its
feature (its target, its viewing direction). As in the authors' planner, the candidates spread at
least `candidate_spacing_m` apart, the best quarter by density, the nearest half and a random
remainder are kept, and the vehicle flies an A* path to the one with the best
density / (1 + flight time). Targets still frontier after two visits of their viewpoint are given
up (as Classic does); when no candidate is reachable, Classic's nearest frontier takes over:
classic-v1's (splatplanner-v1) or classic-v2's (splatplanner-v2), the only difference between the
two versions.
"""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np
import numpy.typing as npt
from pydantic import Field

from planners.api import Observation, Plan, Planner, PlannerConfig, PlannerContext
from planners.astar import PathCache
from planners.classic import ClassicConfig, ClassicPlanner, ClassicV2Config, frontier_fallback
from planners.give_up import GiveUpTracker
from planners.lines import segments_clear
from planners.permutohedral import PermutohedralLattice
from planners.search import IndexArray, shortcut
from planners.splat_features import flight_time, frontier_normals, pool, spread_kernel
from planners.waypoints import nearest_traversable, path_waypoints
from sim.map_view import MapView
from sim.occupancy import VoxelState

FloatArray = npt.NDArray[np.float64]



class SplatConfig(PlannerConfig):
    """SplatPlanner's settings. The paper's public implementation (the authors' `splatplanner`
    ROS package) is the source where the paper gives no number."""

    # Authors' implementation: the lattice's inverse sigma on positions is 1 / 1.0 m.
    sigma_position_m: float = Field(1.0, gt=0.0)
    # Our choice: normals 90 degrees apart (distance sqrt 2) weigh exp(-4) < 0.02 of each
    # other, so a wall's frontier does not count toward a view along the corridor.
    sigma_normal: float = Field(0.5, gt=0.0)
    # Our choice, within the authors' viewpoint search (1.0-3.6 m from the target): 2 m sees a
    # 1.75 m MAZE corridor's width inside the 90 degree field of view, well within 5 m range.
    sensing_distance_m: float = Field(2.0, gt=0.0)
    # Our choice: closer fallbacks when the sensing distance ends in a wall or unknown space.
    fallback_fractions: tuple[float, ...] = (0.5,)
    # Our choice: level viewpoints first, then half a metre up or down (Classic's offsets).
    height_offsets_m: tuple[float, ...] = (0.0, -0.5, 0.5)
    # Our choice: one target per 0.5 m cell of frontier voxels; the filter sees every voxel.
    target_cell_m: float = Field(0.5, gt=0.0)
    # Classic's 30 degrees: a level camera does not clear frontiers it sees too steeply.
    max_normal_elevation_deg: float = Field(30.0, gt=0.0, le=90.0)
    # Our choice, for speed: frontier voxels facing more steeply than 60 degrees (floors and
    # ceilings, a third of WAREHOUSE's frontier) are left out of the lattice. Every query looks
    # level, and such a normal is at least 2 sin(30 deg) = 1 from it: a weight below
    # exp(-1 / (2 sigma_normal²)) = 0.14 at the default sigma. None splats every voxel.
    splat_max_elevation_deg: float | None = Field(60.0, gt=0.0, le=90.0)
    # Our choice, for speed: frontier voxels in one 0.4 m cell with the same normal are
    # splatted once, at their mean position, weighted by their count (positions move by at
    # most 0.35 m, weights by a few per cent at sigma_position_m = 1 m). None splats each.
    pool_cell_m: float | None = Field(0.4, gt=0.0)
    # Authors' implementation (radiusSelection): goals at least 2.5 m apart, at most 350, and
    # after 50 only those above 0.6 of the best density.
    candidate_spacing_m: float = Field(2.5, ge=0.0)
    max_spread_candidates: int = Field(350, ge=1)
    spread_keep_after: int = Field(50, ge=1)
    spread_min_ratio: float = Field(0.6, ge=0.0, le=1.0)
    # Authors' implementation (computeGoals): 20 goals, the best quarter by density, then the
    # nearest half, then the rest shuffled.
    num_candidates: int = Field(20, ge=1)
    # Authors' implementation (computeBestPath): views scoring below 0.01 are skipped.
    min_density: float = Field(0.01, ge=0.0)
    # Classic's give-up rule (`planners.give_up`) for targets that stay frontiers after visits.
    give_up_after: int = Field(2, ge=1)
    give_up_radius_voxels: int = Field(2, ge=0)
    fallback: ClassicConfig = ClassicConfig()


class SplatV2Config(SplatConfig):
    """splatplanner-v2: classic-v2 as the fallback."""

    fallback: ClassicV2Config = ClassicV2Config()


class SplatBase(Planner):
    """The code of every SplatPlanner version; `config_model` picks the version."""

    config_model: ClassVar[type[SplatConfig]] = SplatConfig
    config: SplatConfig

    def reset(self, ctx: PlannerContext) -> None:
        super().reset(ctx)
        self._paths = PathCache()
        self._fallback = ClassicPlanner(self.config.fallback)
        self._fallback.reset(ctx)
        self._give_up = GiveUpTracker(self.config.give_up_after,
                                      self.config.give_up_radius_voxels)
        self._goal: IndexArray | None = None
        self._target: IndexArray | None = None
        self._splat: PermutohedralLattice | None = None
        self._splat_base = 0
        self._splatted = (np.zeros(0, dtype=np.int64), np.zeros((0, 6)), np.zeros(0))

    def plan(self, obs: Observation) -> Plan:
        view = obs.map
        here = view.world_to_index(np.asarray(obs.pose.position)[None])[0]
        given_up = self._give_up.update(here, self._goal, self._target, obs)
        voxels = np.argwhere(view.frontier & ~given_up)
        if len(voxels) == 0:
            return self._fall_back(obs, "no frontier")
        start = nearest_traversable(view.traversable, here)
        if start is None:
            return self._fall_back(obs, "not in traversable space")
        normals = frontier_normals(view, voxels)
        lattice = self._lattice(view, voxels, normals)
        cands = self._candidates(view, voxels, normals, lattice)
        if cands is None:
            return self._fall_back(obs, "no candidate viewpoint", lattice.n_vertices)
        cand_vox, targets, density = cands
        picked = self._pick(obs, cand_vox, density)
        best = self._best_path(obs, start, cand_vox[picked], density[picked])
        if best is None:
            return self._fall_back(obs, "no candidate reachable", lattice.n_vertices)
        which, path, utility = best
        goal, target = cand_vox[picked][which], targets[picked][which]
        self._goal, self._target = goal, target
        target_world = view.index_to_world(target[None])[0]
        waypoints = path_waypoints(view, path, np.asarray(obs.pose.position), target_world)
        return Plan(waypoints, horizon_s=None, info={
            "mode": "splat", "frontier_voxels": len(voxels), "vertices": lattice.n_vertices,
            "candidates": len(cand_vox), "density": float(density[picked][which]),
            "utility": utility,
        })

    def _features(self, points_m: FloatArray, directions: FloatArray) -> FloatArray:
        cfg = self.config
        return np.hstack([points_m / cfg.sigma_position_m, directions / cfg.sigma_normal])

    def _lattice(self, view: MapView, voxels: IndexArray,
                 normals: FloatArray) -> PermutohedralLattice:
        """The lattice of the frontier voxels' (position, normal) features (all but those
        facing more steeply than `splat_max_elevation_deg`), kept from call to call: only
        the pooled points that changed since the previous call are splatted (the old ones
        removed with the opposite weight), so the cost follows the frontier's change."""
        cfg = self.config
        limit = cfg.splat_max_elevation_deg
        if limit is not None:
            keep = np.abs(normals[:, 2]) <= math.sin(math.radians(limit)) + 1e-9
            voxels, normals = voxels[keep], normals[keep]
        cell = 1.0 if cfg.pool_cell_m is None else cfg.pool_cell_m / view.voxel_size
        keys, points, normals, weights = pool(view.index_to_world(voxels), normals, voxels,
                                              max(cell, 1.0), view.shape)
        features = self._features(points, normals)
        lattice = self._splat
        if lattice is None or lattice.n_vertices > 2 * max(self._splat_base, 10_000):
            # First call, or too many vertices left from frontier long gone: start afresh.
            lattice = PermutohedralLattice(features.reshape(-1, 6), weights=weights)
            self._splat, self._splat_base = lattice, lattice.n_vertices
        else:
            old_keys, old_features, old_weights = self._splatted
            pos = np.minimum(np.searchsorted(keys, old_keys), max(len(keys) - 1, 0))
            same = np.zeros(len(old_keys), dtype=np.bool_)
            if len(keys):
                same = keys[pos] == old_keys
                same[same] = (weights[pos[same]] == old_weights[same]) & np.all(
                    features[pos[same]] == old_features[same], axis=1)
            kept = np.zeros(len(keys), dtype=np.bool_)
            kept[pos[same]] = True
            lattice.add(np.vstack([old_features[~same], features[~kept]]),
                        weights=np.concatenate([-old_weights[~same], weights[~kept]]))
        self._splatted = (keys, features, weights)
        return lattice

    def _candidates(self, view: MapView, voxels: IndexArray, normals: FloatArray,
                    lattice: PermutohedralLattice
                    ) -> tuple[IndexArray, IndexArray, FloatArray] | None:
        """Viewpoints behind sampled frontier voxels: (K, 3) viewpoint voxels, (K, 3) target
        voxels and (K,) filtered densities at their features, spread apart, best first."""
        cfg = self.config
        horizontal = np.linalg.norm(normals[:, :2], axis=1)
        steep = math.cos(math.radians(cfg.max_normal_elevation_deg))
        ok = horizontal >= steep - 1e-9
        if not np.any(ok):
            return None
        vox, nrm = voxels[ok], normals[ok]
        # One target per cell: the first voxel (C order) of each cell.
        cell = np.floor(vox * (view.voxel_size / cfg.target_cell_m)).astype(np.int64)
        span = cell.max(axis=0) + 1
        _, first = np.unique((cell[:, 0] * span[1] + cell[:, 1]) * span[2] + cell[:, 2],
                             return_index=True)
        vox, nrm = vox[first], nrm[first]
        target_m = view.index_to_world(vox)
        back = -nrm[:, :2] / np.linalg.norm(nrm[:, :2], axis=1, keepdims=True)
        # Every target tries each distance and height in order; the first traversable one with
        # a clear line of sight is its viewpoint.
        options = [(f * cfg.sensing_distance_m, h) for f in (1.0, *cfg.fallback_fractions)
                   for h in cfg.height_offsets_m]
        # A line of sight may cross any voxel but an occupied one (unknown ones may be free).
        see_through = view.state != VoxelState.OCCUPIED
        chosen = np.full(len(vox), -1, dtype=np.int64)
        view_vox = np.zeros((len(vox), 3), dtype=np.int64)
        shape = np.array(view.shape)
        for n, (dist, dz) in enumerate(options):
            todo = np.flatnonzero(chosen < 0)
            if len(todo) == 0:
                break
            pos = target_m[todo].copy()
            pos[:, :2] += back[todo] * dist
            pos[:, 2] += dz
            idx = view.world_to_index(pos)
            inside = np.all((idx >= 0) & (idx < shape), axis=1)
            todo, idx, pos = todo[inside], idx[inside], pos[inside]
            trav = view.traversable[idx[:, 0], idx[:, 1], idx[:, 2]]
            todo, idx, pos = todo[trav], idx[trav], pos[trav]
            if len(todo) == 0:
                continue
            centres = view.index_to_world(idx)
            clear = segments_clear(view, see_through, centres, target_m[todo])
            chosen[todo[clear]] = n
            view_vox[todo[clear]] = idx[clear]
        good = chosen >= 0
        if not np.any(good):
            return None
        vox, view_vox = vox[good], view_vox[good]
        looks = view.index_to_world(vox) - view.index_to_world(view_vox)
        looks /= np.maximum(np.linalg.norm(looks, axis=1, keepdims=True), 1e-9)
        density = lattice.density(self._features(view.index_to_world(vox), looks))
        keep = density >= cfg.min_density
        if not np.any(keep):
            return None
        vox, view_vox, density = vox[keep], view_vox[keep], density[keep]
        spread = self._spread(view.index_to_world(view_vox), density)
        return view_vox[spread], vox[spread], density[spread]

    def _spread(self, points_m: FloatArray, density: FloatArray) -> IndexArray:
        """Indices of candidates, best density first, each `candidate_spacing_m` from those
        kept before it (the authors' radius selection)."""
        cfg = self.config
        order = np.argsort(-density, kind="stable")
        return spread_kernel(points_m, density, order, cfg.candidate_spacing_m,
                              cfg.max_spread_candidates, cfg.spread_keep_after,
                              float(density[order[0]] * cfg.spread_min_ratio))

    def _pick(self, obs: Observation, cand_vox: IndexArray, density: FloatArray) -> IndexArray:
        """`num_candidates` of the candidates (already best first): the best quarter, then the
        nearest half of the others, then a random draw of the rest."""
        n = self.config.num_candidates
        if len(cand_vox) <= n:
            return np.arange(len(cand_vox))
        quarter, half = n // 4, n // 2
        rest = np.arange(quarter, len(cand_vox))
        d2 = np.sum((self._centres(obs, cand_vox[rest]) - obs.pose.position) ** 2, axis=1)
        by_distance = rest[np.argsort(d2, kind="stable")]
        near = by_distance[:half]
        others = by_distance[half:]
        drawn = self.context.rng.choice(others, size=n - quarter - half, replace=False)
        return np.concatenate([np.arange(quarter), near, np.sort(drawn)])

    @staticmethod
    def _centres(obs: Observation, voxels: IndexArray) -> FloatArray:
        return obs.map.index_to_world(voxels)

    def _best_path(self, obs: Observation, start: IndexArray, cand_vox: IndexArray,
                   density: FloatArray) -> tuple[int, IndexArray, float] | None:
        """The candidate with the best density / (1 + flight time) over its A* path, searched
        best bound first (the straight line's time bounds the path's from below)."""
        view, limits = obs.map, self.context.limits
        here = np.asarray(obs.pose.position, dtype=np.float64)
        straight = np.linalg.norm(self._centres(obs, cand_vox) - here, axis=1)
        bounds = density / (1.0 + np.array([flight_time(np.array([s]), limits.v_max,
                                                        limits.a_max) for s in straight]))
        best: tuple[int, IndexArray, float] | None = None
        for i in np.argsort(-bounds, kind="stable"):
            if best is not None and bounds[i] <= best[2]:
                break
            path, _ = self._paths.path(view.traversable, start, cand_vox[i], view.voxel_size)
            if len(path) == 0:
                continue
            path = shortcut(path, view.traversable)
            pts = np.vstack([here[None], view.index_to_world(path)])
            legs = np.linalg.norm(np.diff(pts, axis=0), axis=1)
            utility = float(density[i]) / (1.0 + flight_time(legs, limits.v_max, limits.a_max))
            if best is None or utility > best[2]:
                best = (int(i), path, utility)
        return best

    def _fall_back(self, obs: Observation, why: str, vertices: int = 0) -> Plan:
        """Classic's nearest frontier, whose own end condition ends the exploration."""
        self._goal, self._target = None, None
        return frontier_fallback(self._fallback, obs, why=why, vertices=vertices)


class SplatPlanner(SplatBase):
    """splatplanner-v1."""

    config_model = SplatConfig
    config: SplatConfig


class SplatPlannerV2(SplatBase):
    """splatplanner-v2."""

    config_model = SplatV2Config
    config: SplatV2Config
