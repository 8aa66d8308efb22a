"""The framework's own checks of a plan's path: against the traversable map when the plan is
accepted, and against what the map has learnt since, while it is flown."""

from __future__ import annotations

import numba
import numpy as np
import numpy.typing as npt

from sim.clearance import clearance_window
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
def _new_obstacle_near(
    state: npt.NDArray[np.uint8], before: npt.NDArray[np.uint8], i: int, j: int, k: int,
    margin: int, min_sq: float,
) -> bool:
    """Some voxel OCCUPIED in `state` but not in `before` has its centre nearer to voxel
    (i, j, k)'s than sqrt(min_sq) voxels."""
    nx, ny, nz = state.shape
    for di in range(-margin, margin + 1):
        ii = i + di
        if ii < 0 or ii >= nx:
            continue
        for dj in range(-margin, margin + 1):
            jj = j + dj
            if jj < 0 or jj >= ny or di * di + dj * dj >= min_sq:
                continue
            for dk in range(-margin, margin + 1):
                kk = k + dk
                if kk < 0 or kk >= nz or di * di + dj * dj + dk * dk >= min_sq:
                    continue
                if state[ii, jj, kk] == _OCCUPIED and before[ii, jj, kk] != _OCCUPIED:
                    return True
    return False


@numba.njit(cache=True)
def _polyline_meets_new_obstacle(
    state: npt.NDArray[np.uint8], before: npt.NDArray[np.uint8], points: npt.NDArray[np.float64],
    margin: int, min_sq: float,
) -> bool:
    """`_new_obstacle_near` any voxel a quarter-voxel sample of the polyline `points` (K, 3),
    in voxel units, falls in, as `segment_in_mask` samples it."""
    nx, ny, nz = state.shape
    last_i, last_j, last_k = -1, -1, -1
    for n in range(points.shape[0]):
        a = points[max(n - 1, 0)]
        b = points[n]
        length = np.sqrt(np.sum((b - a) ** 2))
        steps = max(1, int(np.ceil(length * 4.0)))
        for s in range(steps + 1):
            t = s / steps
            i = int(np.floor(a[0] + (b[0] - a[0]) * t))
            j = int(np.floor(a[1] + (b[1] - a[1]) * t))
            k = int(np.floor(a[2] + (b[2] - a[2]) * t))
            if (i == last_i and j == last_j and k == last_k) or not (
                    0 <= i < nx and 0 <= j < ny and 0 <= k < nz):
                continue
            last_i, last_j, last_k = i, j, k
            if _new_obstacle_near(state, before, i, j, k, margin, min_sq):
                return True
    return False


def path_meets_new_obstacle(
    state: npt.NDArray[np.uint8],
    before: npt.NDArray[np.uint8],
    origin: npt.NDArray[np.float64],
    voxel_size: float,
    radius_m: float,
    points: npt.NDArray[np.float64],
) -> bool:
    """Whether the polyline `points` (K, 3), world metres, now passes within `radius_m` of a
    voxel that has turned OCCUPIED since the map was `before`, both (nx, ny, nz) `VoxelState`.

    Distances are between voxel centres, as in the traversability rule, so a path `plan_is_clear`
    accepted on `before` and flagged here would be rejected if it were planned now (unknown
    voxels were obstacles to it already; only where it escapes from non-traversable space does
    it pass near obstacles at all).
    """
    margin, min_sq = clearance_window(radius_m, voxel_size)
    grid = (np.asarray(points, dtype=np.float64).reshape(-1, 3) - origin) / voxel_size
    return bool(_polyline_meets_new_obstacle(state, before, np.ascontiguousarray(grid), margin,
                                             min_sq))
