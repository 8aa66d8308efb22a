"""The framework's own checks of a plan's path: against the traversable map when the plan is
accepted, and against what the map has learnt since, while it is flown.

Both measure to obstacle voxels' cubes, as the traversable mask does (`sim.clearance`): a plan
is clear when its path stays in voxels whose centres keep the safety radius from every obstacle
cube, and a new obstacle matters to a flight when its cube comes within reach of the path.
"""

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

    A point between two samples lies within an eighth of a voxel of one of them, so the whole
    segment keeps `sim.clearance.guaranteed_clearance_m` less an eighth of a voxel from every
    obstacle cube (at least 0.36 m with 0.1 m voxels and 0.32 m with 0.2 m voxels at the
    benchmark's safety radius, for a 0.30 m vehicle).
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


def starts_traversable(
    traversable: npt.NDArray[np.bool_],
    origin: npt.NDArray[np.float64],
    voxel_size: float,
    start: npt.NDArray[np.float64],
) -> bool:
    """Whether `start` (world (3,)) lies in a traversable voxel, as `plan_is_clear` places it:
    then no leg escapes, and its `free` mask is never read (any array of the grid's shape may
    stand in for it, sparing a pass over the grid to make one)."""
    a = (np.asarray(start, dtype=np.float64) - origin) / voxel_size
    i, j, k = (int(np.floor(v)) for v in a)
    nx, ny, nz = traversable.shape
    return 0 <= i < nx and 0 <= j < ny and 0 <= k < nz and bool(traversable[i, j, k])


def plan_is_clear(
    traversable: npt.NDArray[np.bool_],
    free: npt.NDArray[np.bool_],
    origin: npt.NDArray[np.float64],
    voxel_size: float,
    start: npt.NDArray[np.float64],
    points: npt.NDArray[np.float64],
) -> int:
    """How many leading waypoints can be flown: legs start→p0→p1... stay in traversable voxels
    (`segment_in_mask`).

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


@numba.njit(cache=True, inline="always")
def _point_box_sq(x0: float, x1: float, x2: float, i: int, j: int, k: int) -> float:
    """Squared distance from point x to the cube [i, i+1] x [j, j+1] x [k, k+1]."""
    d0 = max(i - x0, 0.0, x0 - (i + 1))
    d1 = max(j - x1, 0.0, x1 - (j + 1))
    d2 = max(k - x2, 0.0, x2 - (k + 1))
    return d0 * d0 + d1 * d1 + d2 * d2


@numba.njit(cache=True)
def segment_cube_sq(a: npt.NDArray[np.float64], b: npt.NDArray[np.float64], i: int, j: int,
                    k: int) -> float:
    """Squared distance between the segment a→b and the cube of voxel (i, j, k), voxel units.

    Along the segment the squared distance is convex and quadratic between the points where the
    segment crosses a face plane of the cube; its minimum on each such piece is where the
    derivative vanishes, clamped to the piece.
    """
    ab0 = b[0] - a[0]
    ab1 = b[1] - a[1]
    ab2 = b[2] - a[2]
    ts = np.empty(8)
    ts[0] = 0.0
    ts[1] = 1.0
    n = 2
    for axis in range(3):
        o = a[axis]
        d = b[axis] - o
        if d == 0.0:
            continue
        low = float((i, j, k)[axis])
        for bound in (low, low + 1.0):
            t = (bound - o) / d
            if 0.0 < t < 1.0:
                ts[n] = t
                n += 1
    ts[:n].sort()
    best = np.inf
    for s in range(n - 1):
        t0 = ts[s]
        t1 = ts[s + 1]
        mid = 0.5 * (t0 + t1)
        num = 0.0
        den = 0.0
        for axis in range(3):
            o = a[axis]
            d = b[axis] - o
            low = float((i, j, k)[axis])
            x = o + mid * d
            if x < low:
                c = o - low
            elif x > low + 1.0:
                c = o - low - 1.0
            else:
                continue
            num += c * d
            den += d * d
        t = t0 if den == 0.0 else min(max(-num / den, t0), t1)
        best = min(best, _point_box_sq(a[0] + t * ab0, a[1] + t * ab1, a[2] + t * ab2, i, j, k))
    return best


@numba.njit(cache=True)
def _polyline_meets_new_obstacle(
    state: npt.NDArray[np.uint8], before: npt.NDArray[np.uint8], points: npt.NDArray[np.float64],
    reach: float,
) -> bool:
    """Some voxel OCCUPIED in `state` but not in `before` has its cube nearer than `reach` to
    the polyline `points` (K, 3); all in voxel units, voxel (i, j, k) spanning [i, i+1) x
    [j, j+1) x [k, k+1)."""
    nx, ny, nz = state.shape
    reach_sq = reach * reach
    for n in range(points.shape[0]):
        a = points[max(n - 1, 0)]
        b = points[n]
        # The voxels whose cubes can lie within reach of the segment: its box, grown.
        lo0 = max(int(np.floor(min(a[0], b[0]) - reach)) - 1, 0)
        lo1 = max(int(np.floor(min(a[1], b[1]) - reach)) - 1, 0)
        lo2 = max(int(np.floor(min(a[2], b[2]) - reach)) - 1, 0)
        hi0 = min(int(np.floor(max(a[0], b[0]) + reach)), nx - 1)
        hi1 = min(int(np.floor(max(a[1], b[1]) + reach)), ny - 1)
        hi2 = min(int(np.floor(max(a[2], b[2]) + reach)), nz - 1)
        for i in range(lo0, hi0 + 1):
            for j in range(lo1, hi1 + 1):
                for k in range(lo2, hi2 + 1):
                    if state[i, j, k] != _OCCUPIED or before[i, j, k] == _OCCUPIED:
                        continue
                    if segment_cube_sq(a, b, i, j, k) < reach_sq:
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
    """Whether a voxel that has turned OCCUPIED since the map was `before` has its cube nearer
    than `reach_m` to the polyline `points` (K, 3), world metres; `state` and `before` are
    (nx, ny, nz) `VoxelState` grids. A vehicle of radius r flying the path can touch a surface
    in such a voxel only when the voxel's cube comes within r of the path, so r is the reach
    that stops for everything the vehicle could touch and nothing else.
    """
    grid = (np.asarray(points, dtype=np.float64).reshape(-1, 3) - origin) / voxel_size
    return bool(_polyline_meets_new_obstacle(state, before, np.ascontiguousarray(grid),
                                             reach_m / voxel_size))
