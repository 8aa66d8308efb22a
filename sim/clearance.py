"""Voxels a spherical vehicle can occupy, kept up to date from occupancy changes.

A voxel is traversable when it is FREE and its centre lies at least `radius_m` from the centre
of every voxel that is not FREE: UNKNOWN and OCCUPIED voxels are both obstacles, and so is
everything outside the grid. Like `sim.frontiers.FrontierTracker`, the tracker owns a dirty-box
subscription on the map, so both can follow the same integrations at their own pace.
"""

from __future__ import annotations

import math

import numba
import numpy as np
import numpy.typing as npt

from sim.occupancy import IndexBox, OccupancyMap, StateGrid, VoxelState

BoolGrid = npt.NDArray[np.bool_]

_FREE = np.uint8(VoxelState.FREE)
# Distances between voxel centres are square roots of integers (in voxels); the tolerance
# keeps a centre exactly at the radius traversable despite the radius's rounding.
_TOLERANCE_VOXELS = 1e-6


@numba.njit(cache=True)
def _clearance_box(
    state: StateGrid, out: BoolGrid, lo0: int, lo1: int, lo2: int, hi0: int, hi1: int, hi2: int,
    margin: int, min_sq: float,
) -> None:
    """Write `out` on the half-open box [lo, hi): FREE and no obstacle centre nearer than the
    radius, obstacles being non-FREE voxels and every voxel outside the grid.

    The squared distance to the nearest obstacle is separable (a min over x of dx² plus the
    same problem in y, z), and only obstacles within `margin` voxels per axis can be nearer
    than the radius, so three windowed passes of 2 * margin + 1 cells give it exactly.

    state: (nx, ny, nz) uint8 `VoxelState`; out: (nx, ny, nz) bool.
    margin: ceil of the radius in voxels; min_sq: squared radius in voxels, minus a tolerance.
    """
    nx, ny, nz = state.shape
    far = np.int32(3 * (margin + 1) ** 2)  # beyond any distance the radius test looks at
    depth = hi2 - lo2
    best = np.empty(depth, dtype=np.int32)
    blocked = np.empty(depth + 2 * margin, dtype=np.bool_)
    # Loops keep z innermost and the window offset outside it, so the compiler vectorises them.
    # Pass 1 over z, on the box grown by the margin in x and y (clipped to the grid).
    a0 = max(lo0 - margin, 0)
    a1 = max(lo1 - margin, 0)
    b0 = min(hi0 + margin, nx)
    b1 = min(hi1 + margin, ny)
    g1 = np.empty((b0 - a0, b1 - a1, depth), dtype=np.int32)
    for i in range(a0, b0):
        for j in range(a1, b1):
            for t in range(depth + 2 * margin):
                k = lo2 - margin + t
                blocked[t] = k < 0 or k >= nz or state[i, j, k] != _FREE
            best[:] = far
            for d in range(-margin, margin + 1):
                sq = np.int32(d * d)
                for k in range(depth):
                    if blocked[k + margin + d]:
                        best[k] = min(best[k], sq)
            g1[i - a0, j - a1, :] = best
    # Pass 2 over y, on the box grown in x.
    g2 = np.empty((b0 - a0, hi1 - lo1, depth), dtype=np.int32)
    for i in range(b0 - a0):
        for j in range(lo1, hi1):
            best[:] = far
            for d in range(-margin, margin + 1):
                sq = np.int32(d * d)
                jj = j + d
                if jj < 0 or jj >= ny:
                    for k in range(depth):
                        best[k] = min(best[k], sq)
                else:
                    for k in range(depth):
                        best[k] = min(best[k], g1[i, jj - a1, k] + sq)
            g2[i, j - lo1, :] = best
    # Pass 3 over x, on the box itself.
    for i in range(lo0, hi0):
        for j in range(lo1, hi1):
            best[:] = far
            for d in range(-margin, margin + 1):
                sq = np.int32(d * d)
                ii = i + d
                if ii < 0 or ii >= nx:
                    for k in range(depth):
                        best[k] = min(best[k], sq)
                else:
                    for k in range(depth):
                        best[k] = min(best[k], g2[ii - a0, j - lo1, k] + sq)
            for k in range(depth):
                out[i, j, lo2 + k] = state[i, j, lo2 + k] == _FREE and best[k] >= min_sq

class TraversabilityTracker:
    """Traversable voxels of one `OccupancyMap` for a vehicle of radius `radius_m`.

    Args:
        occupancy: the map to follow; the tracker starts from a full computation.
        radius_m: required clearance between a voxel centre and any obstacle voxel centre.
    """

    def __init__(self, occupancy: OccupancyMap, radius_m: float) -> None:
        if not radius_m >= 0.0:
            raise ValueError("radius_m must be non-negative")
        self._map = occupancy
        self._radius_m = float(radius_m)
        self._radius_voxels = self._radius_m / occupancy.voxel_size
        # Obstacles closer than the radius lie within this many voxels on every axis.
        self._margin = max(1, math.ceil(self._radius_voxels - _TOLERANCE_VOXELS))
        self._min_sq = (self._radius_voxels - _TOLERANCE_VOXELS) ** 2 if radius_m > 0 else 0.0
        self._subscription = occupancy.subscribe()
        self._traversable = np.zeros(occupancy.shape, dtype=bool)
        self.full_recompute()

    @property
    def radius_m(self) -> float:
        return self._radius_m

    @property
    def traversable(self) -> BoolGrid:
        """(nx, ny, nz) bool, a read-only view as of the last update."""
        view = self._traversable.view()
        view.setflags(write=False)
        return view

    def update(self) -> IndexBox | None:
        """Recompute where the map changed since the last update.

        Returns:
            The recomputed box (the changed voxels' box grown by the margin), or None when the
            map did not change.
        """
        box = self._subscription.take()
        if box is None:
            return None
        region = box.expanded(self._margin, self._map.shape)
        self._recompute(region)
        return region

    def full_recompute(self) -> None:
        """Recompute the whole grid."""
        self._subscription.take()
        self._recompute(IndexBox.full(self._map.shape))

    def _recompute(self, region: IndexBox) -> None:
        lo, hi = region.lo, region.hi
        _clearance_box(self._map.state, self._traversable, lo[0], lo[1], lo[2], hi[0], hi[1],
                       hi[2], self._margin, self._min_sq)
