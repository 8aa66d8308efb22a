"""FUEL's time cost between poses and the path lengths it is computed on (`planners.fuel`)."""

from __future__ import annotations

import numba
import numpy as np
import numpy.typing as npt

from planners.astar import PathCache
from planners.search import BoolGrid, DistanceField, IndexArray, segment_clear
from sim.map_view import MapView

FloatArray = npt.NDArray[np.float64]


def pose_cost(length_m: npt.ArrayLike, p1: npt.ArrayLike, p2: npt.ArrayLike,
              yaw1: npt.ArrayLike, yaw2: npt.ArrayLike, velocity: FloatArray, v_max: float,
              yaw_rate: float, w_dir: float) -> FloatArray:
    """FUEL's time cost of going from (p1, yaw1) to (p2, yaw2) along paths of `length_m`:
    max(length / v_max + w_dir x angle(velocity, p2 - p1), |yaw change| / yaw_rate), the
    direction term only while moving (speed above 1 mm/s). Arguments broadcast (positions on a
    last axis of 3); returns their broadcast shape."""
    pos_cost = np.asarray(length_m, dtype=np.float64) / v_max
    speed = float(np.linalg.norm(velocity))
    if speed > 1e-3:
        step = np.asarray(p2, dtype=np.float64) - np.asarray(p1, dtype=np.float64)
        dist = np.linalg.norm(step, axis=-1)
        cos = np.sum(step * (velocity / speed), axis=-1) / np.maximum(dist, 1e-12)
        angle = np.where(dist > 1e-9, np.arccos(np.clip(cos, -1.0, 1.0)), 0.0)
        pos_cost = pos_cost + w_dir * angle
    turn = np.asarray(yaw2, dtype=np.float64) - np.asarray(yaw1, dtype=np.float64)
    yaw_cost = np.abs(np.arctan2(np.sin(turn), np.cos(turn))) / yaw_rate
    out: FloatArray = np.maximum(pos_cost, yaw_cost)
    return out


@numba.njit(cache=True)
def _pairs_clear(mask: BoolGrid, a: FloatArray, b: FloatArray) -> npt.NDArray[np.bool_]:
    out = np.zeros((a.shape[0], b.shape[0]), dtype=np.bool_)
    for i in range(a.shape[0]):
        for j in range(b.shape[0]):
            out[i, j] = segment_clear(mask, a[i], b[j])
    return out


class PathLengths:
    """Path lengths between world points for the tour costs: the straight line when it stays in
    traversable voxels, else the length of a shortest 26-connected path on a coarse grid whose
    cells are passable where any of their voxels is traversable (an estimate, as FUEL's coarse
    A*), at least the straight line; inf when not connected. Coarse paths come from `paths`, a
    cache kept from call to call: the path between two viewpoints that did not move is reused
    while it stays passable, as FUEL keeps the costs between unchanged clusters."""

    def __init__(self, view: MapView, cell_m: float, paths: PathCache) -> None:
        self.view = view
        self.factor = max(1, round(cell_m / view.voxel_size))
        f = self.factor
        trav = view.traversable
        pad = [(0, (-n) % f) for n in trav.shape]
        padded = np.pad(trav, pad)
        nx, ny, nz = (n // f for n in padded.shape)
        self.coarse: BoolGrid = np.ascontiguousarray(
            padded.reshape(nx, f, ny, f, nz, f).any(axis=(1, 3, 5)))
        self.cell_m = view.voxel_size * f
        self.paths = paths

    def cells(self, points: FloatArray) -> IndexArray:
        """(N, 3) coarse cells of (N, 3) world points, clipped to the grid."""
        idx = self.view.world_to_index(points) // self.factor
        out: IndexArray = np.clip(idx, 0, np.array(self.coarse.shape) - 1).astype(np.int64)
        return out

    def reachable(self, start: FloatArray, points: FloatArray) -> npt.NDArray[np.bool_]:
        """(N,) whether the coarse grid joins `start` (3,) to each point."""
        field = DistanceField(self.coarse, self.cells(start[None])[0], self.cell_m)
        c = self.cells(points)
        out: npt.NDArray[np.bool_] = np.isfinite(field.dist_m[c[:, 0], c[:, 1], c[:, 2]])
        return out

    def matrix(self, a: FloatArray, b: FloatArray) -> FloatArray:
        """(N, M) path lengths from each of (N, 3) points to each of (M, 3)."""
        view = self.view
        straight = _pairs_clear(view.traversable,
                                np.ascontiguousarray((a - view.origin) / view.voxel_size),
                                np.ascontiguousarray((b - view.origin) / view.voxel_size))
        out: FloatArray = np.linalg.norm(a[:, None, :] - b[None, :, :], axis=2)
        ca, cb = self.cells(a), self.cells(b)
        for i, j in zip(*np.nonzero(~straight), strict=True):
            out[i, j] = max(out[i, j], self._coarse(ca[i], cb[j]))
        return out

    def _coarse(self, a: IndexArray, b: IndexArray) -> float:
        if np.array_equal(a, b):
            return 0.0
        # One cache entry per unordered pair: the grid's paths are symmetric.
        lo, hi = (a, b) if tuple(a) < tuple(b) else (b, a)
        path, length = self.paths.path(self.coarse, lo, hi, self.cell_m)
        return float(length) if len(path) else float("inf")
