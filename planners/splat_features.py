"""SplatPlanner's frontier features (`planners.splat`): frontier voxels' normals into the
unknown, their spreading onto points, and the flight time of a rest-to-rest leg."""

from __future__ import annotations

import numba
import numpy as np
import numpy.typing as npt

from planners.search import IndexArray
from sim.frontier_pieces import unknown_directions
from sim.map_view import MapView

FloatArray = npt.NDArray[np.float64]


def frontier_normals(view: MapView, voxels: IndexArray) -> FloatArray:
    """(F, 3) unit normals of (F, 3) frontier voxels: the normalised sum of the directions to
    their unknown face neighbours (zero where those cancel out)."""
    return unknown_directions(view.state, np.ascontiguousarray(voxels, dtype=np.int64))


@numba.njit(cache=True)
def spread_kernel(points: FloatArray, density: FloatArray, order: IndexArray, spacing: float,
                   max_kept: int, keep_after: int, floor: float) -> IndexArray:
    kept = np.empty(min(max_kept, order.shape[0]), dtype=np.int64)
    n = 0
    r2 = spacing * spacing
    for i in order:
        if n >= keep_after and density[i] < floor:
            break
        near = False
        for m in range(n):
            q = kept[m]
            dx = points[q, 0] - points[i, 0]
            dy = points[q, 1] - points[i, 1]
            dz = points[q, 2] - points[i, 2]
            if dx * dx + dy * dy + dz * dz < r2:
                near = True
                break
        if near:
            continue
        kept[n] = i
        n += 1
        if n >= kept.shape[0]:
            break
    return kept[:n]


def pool(points: FloatArray, normals: FloatArray, voxels: IndexArray, cell_voxels: float,
         shape: tuple[int, int, int]) -> tuple[IndexArray, FloatArray, FloatArray, FloatArray]:
    """Merge (F, 3) points of (F, 3) voxels (on a grid of `shape`) sharing a cell of
    `cell_voxels` voxels and a normal: (P,) sorted group keys, (P, 3) mean points, (P, 3)
    their normal, (P,) counts. Normals of frontier voxels take few values (sums of face
    directions), so the rounded normal identifies them."""
    cell = np.floor(voxels / cell_voxels).astype(np.int64)
    code = np.rint(normals * 4.0).astype(np.int64) + 4
    span = np.array(shape, dtype=np.int64) + 1
    key = ((cell[:, 0] * span[1] + cell[:, 1]) * span[2] + cell[:, 2]) * 729 + (
        code[:, 0] * 81 + code[:, 1] * 9 + code[:, 2])
    keys, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    n = len(counts)
    mean = np.stack([np.bincount(inverse, points[:, a], n) for a in range(3)], axis=1).astype(
        np.float64)
    mean /= counts[:, None]
    first = np.zeros(n, dtype=np.int64)
    first[inverse[::-1]] = np.arange(len(inverse))[::-1]
    return keys, mean, normals[first], counts.astype(np.float64)


def flight_time(lengths_m: FloatArray, v_max: float, a_max: float) -> float:
    """Rest-to-rest time over legs of the given lengths with a trapezoidal speed profile (the
    authors' implementation's estimate)."""
    acc_time = v_max / a_max
    acc_dist = 0.5 * v_max * acc_time
    short = lengths_m < 2.0 * acc_dist
    t = np.where(short, 2.0 * np.sqrt(np.maximum(lengths_m, 0.0) / a_max),
                 2.0 * acc_time + (lengths_m - 2.0 * acc_dist) / v_max)
    return float(np.sum(t))
