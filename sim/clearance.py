"""Voxels a spherical vehicle can occupy, kept up to date from occupancy changes.

A voxel is traversable when it is FREE and its centre lies at least `radius_m` from every point
of every voxel that is not FREE: the distance is to the obstacle voxel's cube, not its centre.
UNKNOWN and OCCUPIED voxels are both obstacles, and so is everything outside the grid. Like
`sim.frontiers.FrontierTracker`, the tracker owns a dirty-box subscription on the map, so both
can follow the same integrations at their own pace.

What a traversable voxel guarantees (`guaranteed_clearance_m`): every point of its cube is at
least the least cube-to-cube distance the rule allows from every obstacle cube, never less than
the radius minus half a voxel diagonal and on the grid more (with the benchmark's 0.45 m safety
radius, 0.374 m at 0.1 m voxels and 0.346 m at 0.2 m voxels). The centre rule this replaces
measured to obstacle centres and let an obstacle cube come within one voxel of a traversable
cube (0.20 m at 0.2 m voxels, less than the 0.30 m vehicle).
"""

from __future__ import annotations

import math

import numba
import numpy as np
import numpy.typing as npt

from sim.occupancy import IndexBox, OccupancyMap, StateGrid, VoxelState

BoolGrid = npt.NDArray[np.bool_]

_FREE = np.uint8(VoxelState.FREE)
# Distances from a voxel centre to another voxel's cube are half-integers per axis (in voxels);
# the tolerance keeps a centre exactly at the radius traversable despite the radius's rounding.
_TOLERANCE_VOXELS = 1e-6


@numba.njit(cache=True)
def _clearance_box(
    state: StateGrid, out: BoolGrid, lo0: int, lo1: int, lo2: int, hi0: int, hi1: int, hi2: int,
    margin: int, min_sq4: float,
) -> None:
    """Write `out` on the half-open box [lo, hi): FREE and no obstacle cube nearer than the
    radius, obstacles being non-FREE voxels and every voxel outside the grid.

    From a voxel centre to the cube of a voxel d voxels away along an axis is max(|d| - 1/2, 0)
    on that axis, so the squared distance is a sum of per-axis terms, and its minimum over the
    obstacles is separable (a min over x of the x term plus the same problem in y, z). Only
    obstacles within `margin` voxels per axis can be nearer than the radius, so three windowed
    passes of 2 * margin + 1 cells give it exactly. The terms are kept as integers,
    (2|d| - 1)^2 = 4 * (|d| - 1/2)^2, and compared with four times the squared radius.

    state: (nx, ny, nz) uint8 `VoxelState`; out: (nx, ny, nz) bool.
    margin: the farthest offset (voxels, per axis) whose cube can be nearer than the radius;
    min_sq4: four times the squared radius in voxels, minus a tolerance.
    """
    nx, ny, nz = state.shape
    far = np.int32(3 * (2 * margin + 1) ** 2)  # beyond any distance the radius test looks at
    depth = hi2 - lo2
    best = np.empty(depth, dtype=np.int32)
    sq = np.empty(2 * margin + 1, dtype=np.int32)
    for d in range(-margin, margin + 1):
        sq[d + margin] = 0 if d == 0 else (2 * abs(d) - 1) ** 2
    # Loops keep z innermost and the window offset outside it, and select rather than branch,
    # so the compiler vectorises them.
    # Pass 1 over z, on the box grown by the margin in x and y (clipped to the grid). `cost`
    # is a column's window: 0 at an obstacle, `far` at a FREE voxel, so max(term, cost) is the
    # term at obstacles and `far` elsewhere. Its cells beyond the grid stay 0 (obstacles).
    a0 = max(lo0 - margin, 0)
    a1 = max(lo1 - margin, 0)
    b0 = min(hi0 + margin, nx)
    b1 = min(hi1 + margin, ny)
    k0 = max(lo2 - margin, 0)
    k1 = min(hi2 + margin, nz)
    t0 = k0 - (lo2 - margin)
    cost = np.zeros(depth + 2 * margin, dtype=np.int32)
    g1 = np.empty((b0 - a0, b1 - a1, depth), dtype=np.int32)
    for i in range(a0, b0):
        for j in range(a1, b1):
            column = state[i, j]
            for k in range(k0, k1):
                cost[t0 + k - k0] = far if column[k] == _FREE else 0
            for k in range(depth):
                best[k] = max(sq[0], cost[k])
            for d in range(1, 2 * margin + 1):
                term = sq[d]
                for k in range(depth):
                    best[k] = min(best[k], max(term, cost[k + d]))
            g1[i - a0, j - a1, :] = best
    # Pass 2 over y, on the box grown in x.
    g2 = np.empty((b0 - a0, hi1 - lo1, depth), dtype=np.int32)
    for i in range(b0 - a0):
        for j in range(lo1, hi1):
            best[:] = far
            for d in range(-margin, margin + 1):
                term = sq[d + margin]
                jj = j + d
                if jj < 0 or jj >= ny:
                    for k in range(depth):
                        best[k] = min(best[k], term)
                else:
                    for k in range(depth):
                        best[k] = min(best[k], g1[i, jj - a1, k] + term)
            g2[i, j - lo1, :] = best
    # Pass 3 over x, on the box itself.
    for i in range(lo0, hi0):
        for j in range(lo1, hi1):
            best[:] = far
            for d in range(-margin, margin + 1):
                term = sq[d + margin]
                ii = i + d
                if ii < 0 or ii >= nx:
                    for k in range(depth):
                        best[k] = min(best[k], term)
                else:
                    for k in range(depth):
                        best[k] = min(best[k], g2[ii - a0, j - lo1, k] + term)
            for k in range(depth):
                out[i, j, lo2 + k] = state[i, j, lo2 + k] == _FREE and best[k] >= min_sq4


def _offsets_within(radius_voxels: float) -> int:
    """The farthest per-axis offset d (voxels) whose cube can lie nearer than the radius to a
    voxel centre: |d| - 1/2 < radius."""
    return max(0, math.ceil(radius_voxels + 0.5 - _TOLERANCE_VOXELS) - 1)


def guaranteed_clearance_m(radius_m: float, voxel_size: float) -> float:
    """The least distance from any point of a traversable voxel's cube to any obstacle cube
    under the rule with `radius_m`: the minimum, over the integer offsets d whose cube the rule
    allows next to a traversable centre (centre-to-cube distance at least the radius), of the
    cube-to-cube distance, sqrt(sum max(|d_a| - 1, 0)^2) voxels.

    Every sample of a path `sim.search_checks.plan_is_clear` accepts lies in a traversable
    voxel, so this much clear of every obstacle cube; the path between samples (a quarter voxel
    apart) at most an eighth of a voxel less.
    """
    r = radius_m / voxel_size - _TOLERANCE_VOXELS
    reach = _offsets_within(radius_m / voxel_size) + 1
    best = math.inf
    for dx in range(reach + 1):
        for dy in range(dx, reach + 1):
            for dz in range(dy, reach + 1):
                centre_sq = sum(max(d - 0.5, 0.0) ** 2 for d in (dx, dy, dz))
                if centre_sq >= r * r:
                    cube = math.sqrt(sum(max(d - 1, 0) ** 2 for d in (dx, dy, dz)))
                    best = min(best, cube)
    return best * voxel_size


class TraversabilityTracker:
    """Traversable voxels of one `OccupancyMap` for a vehicle of radius `radius_m`.

    Args:
        occupancy: the map to follow; the tracker starts from a full computation.
        radius_m: required clearance between a voxel centre and any obstacle voxel's cube.
    """

    def __init__(self, occupancy: OccupancyMap, radius_m: float) -> None:
        if not radius_m >= 0.0:
            raise ValueError("radius_m must be non-negative")
        self._map = occupancy
        self._radius_m = float(radius_m)
        self._radius_voxels = self._radius_m / occupancy.voxel_size
        # Obstacles closer than the radius lie within this many voxels on every axis (at least
        # one, so that a changed voxel's neighbours are recomputed with it).
        self._margin = max(1, _offsets_within(self._radius_voxels))
        self._min_sq4 = 4.0 * (self._radius_voxels - _TOLERANCE_VOXELS) ** 2 \
            if radius_m > 0 else 0.0
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
                       hi[2], self._margin, self._min_sq4)
