"""Frontier voxels of an `OccupancyMap`, kept up to date incrementally, and their clusters.

A frontier voxel is a FREE voxel with at least one UNKNOWN 6-neighbour; voxels outside the grid
do not count as unknown. `FrontierTracker` subscribes to the map's dirty boxes (see
`sim.occupancy.DirtyBoxSubscription`), so it can be refreshed independently of other consumers
such as `sim.clearance.TraversabilityTracker`: each owns its subscription and `update()` costs
time proportional to the box of voxels whose state changed since its previous update.

`FrontierTracker.clusters` keeps the pieces it made (`sim.frontier_pieces`) and, at the next
call, makes again only the components that the voxels recomputed since may have changed; the
others, with their pieces, centroids and normals, are kept as they were: the same clusters, to
the bit, as from scratch.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
import numpy.typing as npt

from sim.frontier_pieces import Pieces, clear_kept, merged, pieces_of, touched_components
from sim.geometry import FloatArray
from sim.occupancy import IndexArray, IndexBox, OccupancyMap, StateGrid, VoxelState

BoolGrid = npt.NDArray[np.bool_]
BitGrid = npt.NDArray[np.uint64]

_UNKNOWN = np.uint8(VoxelState.UNKNOWN)
_FREE = np.uint8(VoxelState.FREE)


@dataclass(frozen=True, eq=False)
class FrontierCluster:
    """A connected group of frontier voxels.

    Attributes:
        id: position in the list `FrontierTracker.clusters` returned; not stable across calls.
        indices: (K, 3) int64 voxel indices, in C order; read-only (the tracker keeps them for
            its next call).
        centroid: (3,) float64 mean of the voxel centres, world metres.
        normal: (3,) float64 unit vector, the normalised mean over the voxels of the unit
            direction toward their UNKNOWN 6-neighbours: it points from known free space into
            the unknown. Zero in the rare case where those directions cancel out.
        size: K.
    """

    id: int
    indices: IndexArray
    centroid: FloatArray
    normal: FloatArray
    size: int


@numba.njit(cache=True)
def _frontier_box(
    state: StateGrid, frontier: BoolGrid, bits: BitGrid,
    lo0: int, lo1: int, lo2: int, hi0: int, hi1: int, hi2: int,
) -> int:
    """Recompute `frontier` on the half-open box [lo, hi) from `state`.

    state: (nx, ny, nz) uint8 `VoxelState`; frontier: (nx, ny, nz) bool, written in the box;
    bits: (ceil(nx*ny*nz / 64),) uint64, the same set one bit per voxel (word v >> 6, bit
    v & 63 of flat C-order index v), kept equal to `frontier`.
    Returns the change in the number of frontier voxels.
    """
    nx, ny, nz = state.shape
    delta = 0
    for i in range(lo0, hi0):
        for j in range(lo1, hi1):
            for k in range(lo2, hi2):
                f = False
                if state[i, j, k] == _FREE:
                    f = (
                        (i > 0 and state[i - 1, j, k] == _UNKNOWN)
                        or (i + 1 < nx and state[i + 1, j, k] == _UNKNOWN)
                        or (j > 0 and state[i, j - 1, k] == _UNKNOWN)
                        or (j + 1 < ny and state[i, j + 1, k] == _UNKNOWN)
                        or (k > 0 and state[i, j, k - 1] == _UNKNOWN)
                        or (k + 1 < nz and state[i, j, k + 1] == _UNKNOWN)
                    )
                if f != frontier[i, j, k]:
                    delta += 1 if f else -1
                    frontier[i, j, k] = f
                    v = (i * ny + j) * nz + k
                    bits[v >> 6] ^= np.uint64(1) << np.uint64(v & 63)
    return delta


# The position of a word's lowest set bit from that bit alone: a de Bruijn sequence's top six
# bits after multiplying by the bit are distinct for each of the 64 positions.
_DE_BRUIJN = 0x03F79D71B4CB0A89
_BIT_AT = np.zeros(64, dtype=np.int64)
for _b in range(64):
    _BIT_AT[((_DE_BRUIJN << _b) & (2**64 - 1)) >> 58] = _b
del _b


@numba.njit(cache=True)
def _true_indices(bits: BitGrid, ny: int, nz: int, count: int) -> IndexArray:
    """(count, 3) int64 indices of the voxels whose bit is set in `bits` (one bit per voxel of
    a (.., ny, nz) grid, as `_frontier_box` keeps them), in C order; count is their number.

    Frontier voxels are a small share of the grid, and this runs at most calls for clusters:
    64 voxels are read at a time, and only the set bits of a word are visited."""
    out = np.empty((count, 3), dtype=np.int64)
    de_bruijn = np.uint64(_DE_BRUIJN)
    p = 0
    for w in range(bits.shape[0]):
        word = bits[w]
        while word != 0:
            low = word & (~word + np.uint64(1))
            v = w * 64 + _BIT_AT[(low * de_bruijn) >> np.uint64(58)]
            word ^= low
            q = v // nz
            out[p, 0] = q // ny
            out[p, 1] = q - (q // ny) * ny
            out[p, 2] = v - q * nz
            p += 1
    return out


class FrontierTracker:
    """Frontier grid of one `OccupancyMap`, refreshed from the map's state changes.

    Args:
        occupancy: the map to follow; the tracker starts from a full computation.
    """

    def __init__(self, occupancy: OccupancyMap) -> None:
        self._map = occupancy
        self._subscription = occupancy.subscribe()
        self._frontier = np.zeros(occupancy.shape, dtype=bool)
        # The same set one bit per voxel (`_frontier_box`): listing the frontier reads 64
        # voxels a word.
        self._bits = np.zeros((self._frontier.size + 63) // 64, dtype=np.uint64)
        self._count = 0
        # The pieces of the last `clusters` call, and the box of every voxel recomputed since
        # (None: none was), so that the next call makes again only the components it touches.
        self._pieces: Pieces | None = None
        self._changed: IndexBox | None = None
        self.full_recompute()

    @property
    def frontier(self) -> BoolGrid:
        """(nx, ny, nz) bool, True on frontier voxels; a read-only view as of the last update."""
        view = self._frontier.view()
        view.setflags(write=False)
        return view

    @property
    def count(self) -> int:
        """Number of frontier voxels as of the last update."""
        return self._count

    def update(self) -> IndexBox | None:
        """Recompute the frontier where the map changed since the last update.

        Returns:
            The recomputed box (the changed voxels' box grown by one voxel), or None when the
            map did not change.
        """
        box = self._subscription.take()
        if box is None:
            return None
        region = box.expanded(1, self._map.shape)
        self._recompute(region)
        return region

    def full_recompute(self) -> None:
        """Recompute the whole frontier grid."""
        self._subscription.take()
        self._frontier[...] = False
        self._bits[...] = 0
        self._count = 0
        self._pieces = None
        self._recompute(IndexBox.full(self._map.shape))

    def _recompute(self, region: IndexBox) -> None:
        lo, hi = region.lo, region.hi
        if region.size:
            self._changed = region if self._changed is None else self._changed.union(region)
        self._count += int(
            _frontier_box(self._map.state, self._frontier, self._bits,
                          lo[0], lo[1], lo[2], hi[0], hi[1], hi[2])
        )

    def clusters(self, min_size: int = 5, max_extent_m: float = 3.0) -> list[FrontierCluster]:
        """Connected groups of frontier voxels of the current map (updates first).

        Args:
            min_size: clusters with fewer voxels are dropped.
            max_extent_m: components wider than this on any axis are cut into pieces no wider,
                so that every centroid stays near its voxels.

        Returns:
            Clusters in C order of their first voxel, with ids 0, 1, ...
        """
        self.update()
        # Taken before the pieces are made again, and the old pieces let go: a call that fails
        # half-way leaves the next one to start from scratch.
        region, self._changed = self._changed, None
        old, self._pieces = self._pieces, None
        if self._count == 0:
            return []
        cell_voxels = max_extent_m / self._map.voxel_size
        if old is not None and old.cell_voxels == cell_voxels:
            pieces = old if region is None else self._pieces_again(old, region)
        else:
            _, ny, nz = self._map.shape
            pieces = self._pieces_of(_true_indices(self._bits, ny, nz, self._count), cell_voxels)
        self._pieces = pieces
        # Each call hands out centroids and normals of its own (rows of fresh arrays), as made
        # from scratch; the voxel lists are read-only views of the kept pieces.
        centroids, normals = pieces.centroid.copy(), pieces.normal.copy()
        result: list[FrontierCluster] = []
        # Only the kept pieces are cut out (most pieces are smaller than `min_size`).
        for p in np.flatnonzero(pieces.size >= min_size):
            start, size = int(pieces.start[p]), int(pieces.size[p])
            result.append(FrontierCluster(
                id=len(result), indices=pieces.grouped[start:start + size],
                centroid=centroids[p], normal=normals[p], size=size,
            ))
        return result

    def _pieces_of(self, indices: IndexArray, cell_voxels: float) -> Pieces:
        """The pieces of whole components `indices` (K, 3), in C order."""
        return pieces_of(indices, self._map.shape, self._map.state, self._map.origin,
                         self._map.voxel_size, cell_voxels)

    def _pieces_again(self, old: Pieces, region: IndexBox) -> Pieces:
        """`old`'s pieces of the components the `region` recomputed since does not touch, and
        the pieces of the rest of the frontier made again (`sim.frontier_pieces`)."""
        kept = ~touched_components(old, region)
        _, ny, nz = self._map.shape
        rest = self._bits.copy()
        cleared = clear_kept(rest, old, kept, ny, nz)
        if cleared == self._count and kept.all():
            return old  # every component kept, and no frontier voxel outside them
        new = self._pieces_of(_true_indices(rest, ny, nz, self._count - cleared), old.cell_voxels)
        return merged(old, kept, new)
