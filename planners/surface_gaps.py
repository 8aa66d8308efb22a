"""Narrow gaps in the map's occupied surfaces, closed for a gain's rays.

Grazing rays sweep holes into a surface's one-voxel occupied layer, and the unknown interior of
a thin wall stays unknown for good. A gain cast through those holes counts that interior, a gain
no flight can reduce, and a planner chasing it stalls (traced for NBVP and ESM on MAZE, see
`docs/planners.md`). `close_surface_gaps` marks every voxel that lies, along some axis, between
two occupied voxels at most `gap_voxels` + 1 apart; the result is only ever cast through by a
gain, never used for collision checks or search.
"""

from __future__ import annotations

import numba
import numpy as np
import numpy.typing as npt

from sim.occupancy import VoxelState

StateGrid = npt.NDArray[np.uint8]

# A voxel in a closed gap: it stops a gain's ray like an occupied voxel, but it is no surface
# that a view could add to the reconstruction (`planners.recon_gain` gives it no worth).
CLOSED_GAP = np.uint8(3)

_OCCUPIED = np.uint8(VoxelState.OCCUPIED)


@numba.njit(cache=True)
def _close_gaps(state: StateGrid, gap: int, closed: StateGrid, fill: np.uint8) -> None:
    """Set `closed` (nx, ny, nz) to `fill` between consecutive occupied voxels of `state` at
    most `gap` + 1 apart along any axis (pairs further apart are covered by consecutive ones).
    One pass over `state` in memory order, keeping the last occupied index seen along each
    axis; `closed` is written only in the gaps, so it starts as a copy of `state`."""
    nx, ny, nz = state.shape
    last_i = np.full((ny, nz), -1, dtype=np.int64)
    last_j = np.empty(nz, dtype=np.int64)
    for i in range(nx):
        last_j[:] = -1
        for j in range(ny):
            last_k = -1
            for k in range(nz):
                if state[i, j, k] != _OCCUPIED:
                    continue
                if last_k >= 0 and 1 < k - last_k <= gap + 1:
                    closed[i, j, last_k + 1:k] = fill
                if last_j[k] >= 0 and 1 < j - last_j[k] <= gap + 1:
                    closed[i, last_j[k] + 1:j, k] = fill
                if last_i[j, k] >= 0 and 1 < i - last_i[j, k] <= gap + 1:
                    closed[last_i[j, k] + 1:i, j, k] = fill
                last_k = k
                last_j[k] = j
                last_i[j, k] = i


def close_surface_gaps(state: StateGrid, gap_voxels: int,
                       fill: int = VoxelState.OCCUPIED) -> StateGrid:
    """(nx, ny, nz) copy of `state` with the gaps of at most `gap_voxels` voxels between two
    occupied voxels along any axis set to `fill` (OCCUPIED, or `CLOSED_GAP` for a gain that
    tells surfaces it could reconstruct from closed gaps). Linear in the grid's size."""
    closed = np.ascontiguousarray(state).copy()
    if gap_voxels > 0:
        _close_gaps(np.ascontiguousarray(state), gap_voxels, closed, np.uint8(fill))
    return closed
