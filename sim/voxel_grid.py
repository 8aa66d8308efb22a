"""The voxel grid's vocabulary, shared by the occupancy map and its ray-casting kernels.

Grid convention: voxel (0, 0, 0) has its lower corner at ``origin`` (3,), metres, world frame;
voxel (i, j, k) spans ``origin + [i, j, k] * voxel_size`` to ``origin + [i+1, j+1, k+1] *
voxel_size``. A point on a voxel face belongs to the voxel on its upper side (floor rule).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np
import numpy.typing as npt

IndexArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]
StateGrid = npt.NDArray[np.uint8]
LogOddsGrid = npt.NDArray[np.float32]


class VoxelState(IntEnum):
    """Value of a voxel in `OccupancyMap.state`."""

    UNKNOWN = 0
    FREE = 1
    OCCUPIED = 2


_UNKNOWN = np.uint8(VoxelState.UNKNOWN)
_FREE = np.uint8(VoxelState.FREE)
_OCCUPIED = np.uint8(VoxelState.OCCUPIED)



@dataclass(frozen=True)
class IndexBox:
    """Half-open box of voxel indices: ``lo[a] <= index[a] < hi[a]`` on each axis a."""

    lo: tuple[int, int, int]
    hi: tuple[int, int, int]

    @property
    def shape(self) -> tuple[int, int, int]:
        return (self.hi[0] - self.lo[0], self.hi[1] - self.lo[1], self.hi[2] - self.lo[2])

    @property
    def size(self) -> int:
        """Number of voxels in the box (0 when empty)."""
        sx, sy, sz = self.shape
        return max(sx, 0) * max(sy, 0) * max(sz, 0)

    def slices(self) -> tuple[slice, slice, slice]:
        """Index the box in a (nx, ny, nz) array."""
        return (
            slice(self.lo[0], self.hi[0]),
            slice(self.lo[1], self.hi[1]),
            slice(self.lo[2], self.hi[2]),
        )

    def union(self, other: IndexBox) -> IndexBox:
        lo = (min(self.lo[0], other.lo[0]), min(self.lo[1], other.lo[1]),
              min(self.lo[2], other.lo[2]))
        hi = (max(self.hi[0], other.hi[0]), max(self.hi[1], other.hi[1]),
              max(self.hi[2], other.hi[2]))
        return IndexBox(lo, hi)

    def expanded(self, margin: int, shape: tuple[int, int, int]) -> IndexBox:
        """The box grown by `margin` voxels on every side, clipped to a grid of `shape`."""
        lo = (max(self.lo[0] - margin, 0), max(self.lo[1] - margin, 0),
              max(self.lo[2] - margin, 0))
        hi = (min(self.hi[0] + margin, shape[0]), min(self.hi[1] + margin, shape[1]),
              min(self.hi[2] + margin, shape[2]))
        return IndexBox(lo, hi)

    @staticmethod
    def full(shape: tuple[int, int, int]) -> IndexBox:
        return IndexBox((0, 0, 0), (int(shape[0]), int(shape[1]), int(shape[2])))


class DirtyBoxSubscription:
    """The box of voxels whose state changed since this subscriber's last `take()`."""

    def __init__(self) -> None:
        self._box: IndexBox | None = None

    def merge(self, box: IndexBox) -> None:
        self._box = box if self._box is None else self._box.union(box)

    def peek(self) -> IndexBox | None:
        return self._box

    def take(self) -> IndexBox | None:
        """The accumulated box (None when nothing changed), then reset."""
        box, self._box = self._box, None
        return box
