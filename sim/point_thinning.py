"""One point per grid cell, the first of each cell in the points' order, in time linear in the
number of points (the recording's surface snapshots thin millions of points)."""

from __future__ import annotations

import math

import numba
import numpy as np
import numpy.typing as npt


@numba.njit(cache=True)
def _first_of_each_cell(points: npt.NDArray[np.float64], cell_m: float) -> npt.NDArray[np.bool_]:
    """(N,) True at the first point (N, 3) of each cell, cells numbered as
    `first_in_each_cell` describes."""
    n = points.shape[0]
    lo = np.full(3, np.iinfo(np.int64).max, dtype=np.int64)
    hi = np.full(3, np.iinfo(np.int64).min, dtype=np.int64)
    for i in range(n):
        for a in range(3):
            c = np.int64(math.floor(points[i, a] / cell_m))
            lo[a] = min(lo[a], c)
            hi[a] = max(hi[a], c)
    span1 = hi[1] - lo[1] + 1
    span2 = hi[2] - lo[2] + 1
    size = 2
    while size < 2 * n:
        size *= 2
    mask = np.uint64(size - 1)
    table = np.full(size, -1, dtype=np.int64)  # open addressing, linear probing
    first = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        c0 = np.int64(math.floor(points[i, 0] / cell_m)) - lo[0]
        c1 = np.int64(math.floor(points[i, 1] / cell_m)) - lo[1]
        c2 = np.int64(math.floor(points[i, 2] / cell_m)) - lo[2]
        key = (c0 * span1 + c1) * span2 + c2
        slot = ((np.uint64(key) * np.uint64(0x9E3779B97F4A7C15)) >> np.uint64(20)) & mask
        while True:
            held = table[slot]
            if held == -1:
                table[slot] = key
                first[i] = True
                break
            if held == key:
                break
            slot = (slot + np.uint64(1)) & mask
    return first


def first_in_each_cell(points: npt.NDArray[np.float64], cell_m: float) -> npt.NDArray[np.float64]:
    """The points (N, 3), keeping only the first of each cube `floor(point / cell_m)`, in their
    order. Finite points only."""
    if len(points) == 0:
        return points
    return points[_first_of_each_cell(np.ascontiguousarray(points, dtype=np.float64), cell_m)]
