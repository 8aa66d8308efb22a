"""The framework's own check of a plan's path against the traversable map."""

from __future__ import annotations

import numba
import numpy as np
import numpy.typing as npt


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
