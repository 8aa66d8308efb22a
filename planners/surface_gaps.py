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
def _gap_mask(state: StateGrid, gap: int) -> npt.NDArray[np.bool_]:
    """(nx, ny, nz) True between consecutive occupied voxels at most `gap` + 1 apart along
    any axis (pairs further apart are covered by consecutive ones). One pass in memory order,
    keeping the last occupied index seen along each axis."""
    nx, ny, nz = state.shape
    mask = np.zeros(state.shape, dtype=np.bool_)
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
                    mask[i, j, last_k + 1:k] = True
                if last_j[k] >= 0 and 1 < j - last_j[k] <= gap + 1:
                    mask[i, last_j[k] + 1:j, k] = True
                if last_i[j, k] >= 0 and 1 < i - last_i[j, k] <= gap + 1:
                    mask[last_i[j, k] + 1:i, j, k] = True
                last_k = k
                last_j[k] = j
                last_i[j, k] = i
    return mask


def close_surface_gaps(state: StateGrid, gap_voxels: int,
                       fill: int = VoxelState.OCCUPIED) -> StateGrid:
    """(nx, ny, nz) copy of `state` with the gaps of at most `gap_voxels` voxels between two
    occupied voxels along any axis set to `fill` (OCCUPIED, or `CLOSED_GAP` for a gain that
    tells surfaces it could reconstruct from closed gaps). Linear in the grid's size."""
    closed = state.copy()
    if gap_voxels > 0:
        closed[_gap_mask(np.ascontiguousarray(state), gap_voxels)] = fill
    return closed
