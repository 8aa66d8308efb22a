"""The framework's own checks of a plan's path: against the traversable map when the plan is
accepted, and against what the map has learnt since, while it is flown."""

from __future__ import annotations

import numba
import numpy as np
import numpy.typing as npt

from sim.occupancy import VoxelState

_OCCUPIED = np.uint8(VoxelState.OCCUPIED)


@numba.njit(cache=True)
def segment_in_mask(
    traversable: npt.NDArray[np.bool_],
    free: npt.NDArray[np.bool_],
    a: npt.NDArray[np.float64],
    b: npt.NDArray[np.float64],
    escaping: bool,
) -> bool:
    """Every quarter-voxel sample of a→b (voxel units) lies in a traversable voxel. While
    `escaping`, samples before the first traversable one need only be known free.

    Quarter-voxel samples never miss a voxel the segment crosses by more than a sliver, which
    the safety margin of the traversable mask absorbs.
    """
    nx, ny, nz = traversable.shape
    length = np.sqrt(np.sum((b - a) ** 2))
    steps = max(1, int(np.ceil(length * 4.0)))
    for s in range(steps + 1):
        t = s / steps
        i = int(np.floor(a[0] + (b[0] - a[0]) * t))
        j = int(np.floor(a[1] + (b[1] - a[1]) * t))
        k = int(np.floor(a[2] + (b[2] - a[2]) * t))
        if i < 0 or j < 0 or k < 0 or i >= nx or j >= ny or k >= nz:
            return False
        if traversable[i, j, k]:
            escaping = False
        elif not (escaping and free[i, j, k]):
            return False
    return True


def plan_is_clear(
    traversable: npt.NDArray[np.bool_],
    free: npt.NDArray[np.bool_],
    origin: npt.NDArray[np.float64],
    voxel_size: float,
    start: npt.NDArray[np.float64],
    points: npt.NDArray[np.float64],
) -> int:
    """How many leading waypoints can be flown: legs start→p0→p1... stay in traversable voxels.

    The vehicle may stand where the map no longer allows (the map changed around it, or odometry
    drifted): the first leg may then cross known free voxels until it enters traversable space.
    """
    previous = (np.asarray(start, dtype=np.float64) - origin) / voxel_size
    for n, p in enumerate(np.asarray(points, dtype=np.float64)):
        current = (p - origin) / voxel_size
        if not segment_in_mask(traversable, free, previous, current, n == 0):
            return n
        previous = current
    return len(points)


@numba.njit(cache=True)
def _polyline_meets_new_obstacle(
    state: npt.NDArray[np.uint8], before: npt.NDArray[np.uint8], points: npt.NDArray[np.float64],
    reach: float,
) -> bool:
    """Some voxel OCCUPIED in `state` but not in `before` has its centre within `reach` of the
    polyline `points` (K, 3); all in voxel units, voxel (i, j, k) centred at (i, j, k) + 0.5."""
    nx, ny, nz = state.shape
    reach_sq = reach * reach
    for n in range(points.shape[0]):
        a = points[max(n - 1, 0)]
        b = points[n]
        ab = b - a
        length_sq = ab[0] * ab[0] + ab[1] * ab[1] + ab[2] * ab[2]
        # The voxels whose centres can lie within reach of the segment: its box, grown.
        lo0 = max(int(np.floor(min(a[0], b[0]) - reach - 0.5)), 0)
        lo1 = max(int(np.floor(min(a[1], b[1]) - reach - 0.5)), 0)
        lo2 = max(int(np.floor(min(a[2], b[2]) - reach - 0.5)), 0)
        hi0 = min(int(np.ceil(max(a[0], b[0]) + reach - 0.5)), nx - 1)
        hi1 = min(int(np.ceil(max(a[1], b[1]) + reach - 0.5)), ny - 1)
        hi2 = min(int(np.ceil(max(a[2], b[2]) + reach - 0.5)), nz - 1)
        for i in range(lo0, hi0 + 1):
            for j in range(lo1, hi1 + 1):
                for k in range(lo2, hi2 + 1):
                    if state[i, j, k] != _OCCUPIED or before[i, j, k] == _OCCUPIED:
                        continue
                    c0 = i + 0.5 - a[0]
                    c1 = j + 0.5 - a[1]
                    c2 = k + 0.5 - a[2]
                    t = 0.0
                    if length_sq > 0.0:
                        t = min(max((c0 * ab[0] + c1 * ab[1] + c2 * ab[2]) / length_sq, 0.0),
                                1.0)
                    d0 = c0 - t * ab[0]
                    d1 = c1 - t * ab[1]
                    d2 = c2 - t * ab[2]
                    if d0 * d0 + d1 * d1 + d2 * d2 < reach_sq:
                        return True
    return False


def path_meets_new_obstacle(
    state: npt.NDArray[np.uint8],
    before: npt.NDArray[np.uint8],
    origin: npt.NDArray[np.float64],
    voxel_size: float,
    reach_m: float,
    points: npt.NDArray[np.float64],
) -> bool:
    """Whether a voxel that has turned OCCUPIED since the map was `before` has its centre within
    `reach_m` of the polyline `points` (K, 3), world metres; `state` and `before` are
    (nx, ny, nz) `VoxelState` grids. A vehicle of radius r flying the path can touch a surface
    in such a voxel only when its centre lies within r plus half the voxel's diagonal.
    """
    grid = (np.asarray(points, dtype=np.float64).reshape(-1, 3) - origin) / voxel_size
    return bool(_polyline_meets_new_obstacle(state, before, np.ascontiguousarray(grid),
                                             reach_m / voxel_size))
