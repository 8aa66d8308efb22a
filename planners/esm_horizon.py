"""ESM with the original's local horizon: `esm-ipp-v2`, `esm-recon-v2` and their v3.

`planners.esm.Esm` (v1) with four changes, each the authors' public code or the FLYBO authors'
configuration of it (`planners.esm_horizon_config`):

- **Local gain updates.** At each replan the original re-evaluates the views within
  `update_range` of the vehicle (`YawPlanningEvaluator::updateSegment`); a node farther away keeps
  the gain it was given. v1 recomputed every stale gain on the way to the best branch, wherever it
  lay, which grows with the explored area; here the best-first search recomputes only stale nodes
  within `update_range_m` of the vehicle, so it touches a bounded neighbourhood.
- **Minimum segment length.** The original's `connectPoses` refuses a segment shorter than
  `min_path_length`, for a new node and for the RRT* rewiring alike (`min_segment_m`).
- **The large-area tree.** On areas mapped at 0.2 m the tree of the FLYBO authors' WAREHOUSE and
  POWERPLANT configuration: 3 m segments, 2 m density, a 6 m update range. v3 grows it on
  outdoor areas too, as the FLYBO authors did on PLATFORM A.
- **Nearest-node queries by k-d tree.** Sampling looks up nearest nodes in a k-d tree built once
  per call (the original keeps a nanoflann k-d tree of the segments), so a try costs O(log N)
  instead of a pass over every node.
"""

from __future__ import annotations

import dataclasses
import math
from typing import ClassVar

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from planners.api import Observation, Plan, PlannerContext
from planners.esm import Esm
from planners.esm_horizon_config import (
    EsmHorizonConfig,
    EsmHorizonV3Config,
    EsmReconHorizonConfig,
    EsmReconHorizonV3Config,
)
from planners.esm_screen import SteerRule
from planners.segment_tree import BoolArray, SegmentTree
from sim.map_view import MapView

FloatArray = npt.NDArray[np.float64]


class NodeIndex:
    """Nearest-node queries over a tree's positions: a k-d tree of the nodes there were when it
    was built, plus the few added since (searched directly)."""

    def __init__(self, positions: FloatArray) -> None:
        self._built = len(positions)
        self._kd = cKDTree(positions) if self._built else None

    def nearest(self, positions: FloatArray, point: FloatArray, count: int) -> npt.NDArray[np.intp]:
        """Ids of the (at most) `count` nodes of `positions` nearest to `point`, nearest first."""
        ids: list[npt.NDArray[np.intp]] = []
        d: list[FloatArray] = []
        if self._kd is not None:
            k = min(count, self._built)
            dist, idx = self._kd.query(point, k=k)
            ids.append(np.atleast_1d(np.asarray(idx, dtype=np.intp)))
            d.append(np.atleast_1d(np.asarray(dist, dtype=np.float64)))
        if len(positions) > self._built:
            recent = np.arange(self._built, len(positions), dtype=np.intp)
            ids.append(recent)
            d.append(np.linalg.norm(positions[recent] - point, axis=1))
        if not ids:
            return np.zeros(0, dtype=np.intp)
        all_ids, all_d = np.concatenate(ids), np.concatenate(d)
        order = np.argsort(all_d, kind="stable")[:count]
        result: npt.NDArray[np.intp] = all_ids[order]
        return result

    def min_distance(self, positions: FloatArray, point: FloatArray) -> float:
        """Distance from `point` to the nearest node of `positions`."""
        near = self.nearest(positions, point, 1)
        return float(np.linalg.norm(positions[near[0]] - point)) if len(near) else math.inf


class EsmHorizonPlanner(Esm):
    """ESM with the original's local gain updates and minimum segment length (module doc): the
    code of v2 and v3, whose config models pick the version."""

    config_model: ClassVar[type[EsmHorizonConfig]] = EsmHorizonConfig
    config: EsmHorizonConfig

    def reset(self, ctx: PlannerContext) -> None:
        super().reset(ctx)
        self._indoor = ctx.indoor
        self._resolved = False
        self._index: NodeIndex | None = None
        self._expanding = False

    def plan(self, obs: Observation) -> Plan:
        if not self._resolved:
            # The map's voxel size is known from the first observation on.
            self.config = self.config.for_area(obs.map.voxel_size, self._indoor)
            self._resolved = True
        return super().plan(obs)

    def _clear(self, a: FloatArray, b: FloatArray) -> BoolArray:
        ok = super()._clear(a, b)
        if self._expanding and self.config.min_segment_m > 0.0:
            # New segments and RRT* connections made while growing the tree: the original's
            # connectPoses refuses those shorter than min_path_length.
            length = np.linalg.norm(np.atleast_2d(b) - np.atleast_2d(a), axis=1)
            ok = ok & (length >= self.config.min_segment_m)
        return ok

    def _expand(self, tree: SegmentTree, obs: Observation) -> int:
        self._index = NodeIndex(tree.positions.copy())
        self._expanding = True
        try:
            return super()._expand(tree, obs)
        finally:
            self._expanding = False
            self._index = None

    def _steer(self, tree: SegmentTree, view: MapView, sample: FloatArray) -> FloatArray | None:
        """As v1's, with the nearest nodes and the density test from the k-d tree."""
        cfg, index = self.config, self._index
        if index is None:
            return super()._steer(tree, view, sample)
        positions = tree.positions
        for node in index.nearest(positions, sample, min(cfg.steer_candidates, tree.size)):
            new = self._crop(view, positions[node], sample)
            if new is None:
                continue
            if index.min_distance(positions, new) >= cfg.density_radius_m:
                return new
        return None

    def _crop(self, view: MapView, start: FloatArray, sample: FloatArray) -> FloatArray | None:
        """As v1's, refusing a segment shorter than `min_segment_m` (the original checks the
        sample's distance first, then the cropped segment's)."""
        minimum = self.config.min_segment_m
        if float(np.linalg.norm(sample - start)) < minimum:
            return None
        point = super()._crop(view, start, sample)
        if point is None or float(np.linalg.norm(point - start)) < minimum:
            return None
        return point

    def _steer_rule(self) -> SteerRule:
        return dataclasses.replace(super()._steer_rule(),
                                   min_segment_m=self.config.min_segment_m)

    def _refreshable(self, tree: SegmentTree) -> npt.NDArray[np.bool_] | None:
        """Only nodes within `update_range_m` of the root have their stale gains recomputed:
        farther gains stay as they were (the original's update range)."""
        reach = self.config.update_range_m
        if reach is None:
            return None
        root = tree.positions[tree.root]
        near: npt.NDArray[np.bool_] = np.sum((tree.positions - root) ** 2, axis=1) <= reach * reach
        return near


class EsmHorizon(EsmHorizonPlanner):
    """`esm-ipp-v2`."""


class EsmReconHorizon(EsmHorizonPlanner):
    """`esm-recon-v2`: ESM-Recon with the local horizon, the reconstruction gain."""

    config_model = EsmReconHorizonConfig


class EsmHorizonV3(EsmHorizonPlanner):
    """`esm-ipp-v3`: v2 with the large-area tree on outdoor areas too."""

    config_model = EsmHorizonV3Config


class EsmReconHorizonV3(EsmHorizonPlanner):
    """`esm-recon-v3`: `esm-ipp-v3`'s tree with the reconstruction gain."""

    config_model = EsmReconHorizonV3Config
