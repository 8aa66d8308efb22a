"""How much two layout seeds of one generated area differ: the share of occupied voxels that
differ between them, on the area's ground-truth voxel grid.

Occupied voxels are those `areas.ground_truth.blocked_voxels` marks (centre within half a voxel
of the mesh). Two seeds of a family share their bounds and voxel size, hence their grid; the
share is |A xor B| / |A or B| (0: the same layout, 1: no occupied voxel in common), so a seed that
only jitters a few parts scores near 0.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from areas.area import Area

BoolArray = npt.NDArray[np.bool_]

# Two seeds of every generated area differ in at least this share of occupied voxels (the
# smallest measured is higher: `benchmarks/heldout_difference.py`, docs/areas.md).
MIN_LAYOUT_DIFFERENCE = 0.05


class GridMismatchError(ValueError):
    """The two areas lie on different voxel grids, so their voxels cannot be compared."""


def occupied_voxels(area: Area) -> BoolArray:
    """(nx, ny, nz) bool: the voxels the area's mesh occupies, on its ground-truth grid."""
    from areas.ground_truth import blocked_voxels  # Open3D, on use

    return blocked_voxels(area)


def occupied_difference(a: BoolArray, b: BoolArray) -> float:
    """|a xor b| / |a or b| of two occupancy grids of one shape; 0.0 when both are empty."""
    if a.shape != b.shape:
        raise GridMismatchError(f"grids of shapes {a.shape} and {b.shape} cannot be compared")
    union = int(np.count_nonzero(a | b))
    if union == 0:
        return 0.0
    return int(np.count_nonzero(a ^ b)) / union


def layout_difference(a: Area, b: Area) -> float:
    """The share of occupied voxels that differ between areas `a` and `b` (see the module).

    Raises:
        GridMismatchError: when their bounds or voxel sizes differ.
    """
    same_grid = (a.voxel_size == b.voxel_size and np.array_equal(a.bounds_min, b.bounds_min)
                 and np.array_equal(a.bounds_max, b.bounds_max))
    if not same_grid:
        raise GridMismatchError(f"areas {a.name!r} and {b.name!r} lie on different grids")
    return occupied_difference(occupied_voxels(a), occupied_voxels(b))
