"""Frontier voxels of an `OccupancyMap`, kept up to date incrementally, and their clusters.

A frontier voxel is a FREE voxel with at least one UNKNOWN 6-neighbour; voxels outside the grid
do not count as unknown. `FrontierTracker` subscribes to the map's dirty boxes (see
`sim.occupancy.DirtyBoxSubscription`), so it can be refreshed independently of other consumers
such as `sim.clearance.TraversabilityTracker`: each owns its subscription and `update()` costs
time proportional to the box of voxels whose state changed since its previous update.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
import numpy.typing as npt

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
        indices: (K, 3) int64 voxel indices, in C order.
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


@numba.njit(cache=True)
def _unknown_directions(state: StateGrid, indices: IndexArray) -> FloatArray:
    """(K, 3) unit direction from each voxel toward its UNKNOWN 6-neighbours (zero if none).

    state: (nx, ny, nz) uint8 `VoxelState`; indices: (K, 3) int64 in-grid voxels.
    """
    nx, ny, nz = state.shape
    out = np.zeros((indices.shape[0], 3))
    for p in range(indices.shape[0]):
        i, j, k = indices[p, 0], indices[p, 1], indices[p, 2]
        x = 0.0
        y = 0.0
        z = 0.0
        if i > 0 and state[i - 1, j, k] == _UNKNOWN:
            x -= 1.0
        if i + 1 < nx and state[i + 1, j, k] == _UNKNOWN:
            x += 1.0
        if j > 0 and state[i, j - 1, k] == _UNKNOWN:
            y -= 1.0
        if j + 1 < ny and state[i, j + 1, k] == _UNKNOWN:
            y += 1.0
        if k > 0 and state[i, j, k - 1] == _UNKNOWN:
            z -= 1.0
        if k + 1 < nz and state[i, j, k + 1] == _UNKNOWN:
            z += 1.0
        norm = math.sqrt(x * x + y * y + z * z)
        if norm > 0.0:
            out[p, 0] = x / norm
            out[p, 1] = y / norm
            out[p, 2] = z / norm
    return out


@numba.njit(cache=True)
def _label_sums(state: StateGrid, indices: IndexArray, labels: IndexArray, n: int,
                origin: FloatArray, voxel_size: float) -> tuple[FloatArray, FloatArray]:
    """Per label, the (n, 3) sums of its voxels' `_unknown_directions` and of their centres
    (world: origin + (index + 0.5) * voxel_size), added in the order of `indices` (K, 3); one
    pass instead of a grid of directions and centres and six weighted counts."""
    directions = _unknown_directions(state, indices)
    dir_sums = np.zeros((n, 3))
    centre_sums = np.zeros((n, 3))
    for p in range(indices.shape[0]):
        lab = labels[p]
        for a in range(3):
            dir_sums[lab, a] += directions[p, a]
            centre_sums[lab, a] += origin[a] + (indices[p, a] + 0.5) * voxel_size
    return dir_sums, centre_sums


@numba.njit(cache=True)
def _find(parent: IndexArray, p: int) -> int:
    """Root of p in the union-find forest `parent`, compressing the path on the way."""
    root = p
    while parent[root] != root:
        root = parent[root]
    while parent[p] != root:
        nxt = parent[p]
        parent[p] = root
        p = nxt
    return root


@numba.njit(cache=True, inline="always")
def _union(parent: IndexArray, q: int, p: int) -> None:
    """Join the sets of q and p; the root of the union is its smallest member."""
    rq = _find(parent, q)
    rp = _find(parent, p)
    if rp != rq:
        parent[max(rp, rq)] = min(rp, rq)


@numba.njit(cache=True)
def _pairs_and_components(indices: IndexArray, ny: int, nz: int
                          ) -> tuple[npt.NDArray[np.int32], IndexArray, int]:
    """(M, 2) int32 every pair (q, p), q < p, of 26-neighbours among the voxels, by p then by
    q's row; and the 26-connected components they form: (K,) int64 labels numbered in C order
    of each component's first voxel, and their number (`_joined` over the pairs with one key
    for all, the components joined as the pairs are found rather than in a second pass).

    indices: (K, 3) int64 distinct voxels of a grid with `ny` x `nz` columns, in C order.
    """
    count = indices.shape[0]
    flat = np.empty(count, dtype=np.int64)
    for p in range(count):
        flat[p] = (indices[p, 0] * ny + indices[p, 1]) * nz + indices[p, 2]
    parent = np.arange(count)
    # Each pair is found once, from its later voxel: only the 13 neighbours before p in C
    # order are looked for: (i, j, k - 1), which can only be p - 1, and four rows of three
    # (i - 1 with j - 1, j, j + 1; i with j - 1; each k - 1 .. k + 1). The voxels are sorted, so
    # where each row starts moves forward with p: one cursor per row walks the list once, in
    # place of a lookup grid the size of the map (random reads over the whole grid).
    rows_i = (-1, -1, -1, 0)
    rows_j = (-1, 0, 1, -1)
    cursor = np.zeros(4, dtype=np.int64)
    pairs = np.empty((13 * count, 2), dtype=np.int32)
    m = 0
    for p in range(count):
        i, j, k = indices[p, 0], indices[p, 1], indices[p, 2]
        if k > 0 and p > 0 and flat[p - 1] == flat[p] - 1:
            pairs[m, 0] = p - 1
            pairs[m, 1] = p
            m += 1
            _union(parent, p - 1, p)
        for row in range(4):
            a = i + rows_i[row]
            b = j + rows_j[row]
            if a < 0 or b < 0 or b >= ny:
                continue
            base = (a * ny + b) * nz
            first = base + max(k - 1, 0)
            last = base + min(k + 1, nz - 1)
            q = cursor[row]
            while q < p and flat[q] < first:
                q += 1
            cursor[row] = q
            while q < p and flat[q] <= last:
                pairs[m, 0] = q
                pairs[m, 1] = p
                m += 1
                _union(parent, q, p)
                q += 1
    labels, n = _numbered(parent)
    return pairs[:m], labels, n


@numba.njit(cache=True)
def _numbered(parent: IndexArray) -> tuple[IndexArray, int]:
    """(count,) int64 labels 0 .. n-1 of the sets of the union-find forest `parent`, numbered in
    C order of each set's first voxel, and n."""
    # Each root is its set's smallest member, so numbering roots in order follows C order.
    count = parent.shape[0]
    labels = np.empty(count, dtype=np.int64)
    n = 0
    for p in range(count):
        root = _find(parent, p)
        if root == p:
            labels[p] = n
            n += 1
        else:
            labels[p] = labels[root]
    return labels, n


@numba.njit(cache=True)
def _joined(pairs: npt.NDArray[np.int32], key: IndexArray, count: int) -> tuple[IndexArray, int]:
    """Components of `count` voxels joined by the `pairs` (M, 2) whose two voxels have equal
    `key` (count,): (count,) int64 labels 0 .. n-1 numbered in C order of each component's
    first voxel, and n."""
    parent = np.arange(count)
    for e in range(pairs.shape[0]):
        q, p = pairs[e, 0], pairs[e, 1]
        if key[q] == key[p]:
            _union(parent, q, p)
    return _numbered(parent)


@numba.njit(cache=True)
def _label_boxes(indices: IndexArray, labels: IndexArray, n: int) -> tuple[IndexArray, IndexArray]:
    """(n, 3) min and (n, 3) max voxel index of each label; indices (K, 3), labels (K,)."""
    lo = np.full((n, 3), np.iinfo(np.int64).max)
    hi = np.full((n, 3), -1)
    for p in range(indices.shape[0]):
        lab = labels[p]
        for a in range(3):
            lo[lab, a] = min(lo[lab, a], indices[p, a])
            hi[lab, a] = max(hi[lab, a], indices[p, a])
    return lo, hi


@numba.njit(cache=True)
def _grouped(indices: IndexArray, labels: IndexArray, sizes: IndexArray) -> IndexArray:
    """(K, 3) the voxels `indices` (K, 3) ordered by label (K,) and in their given order within
    a label (a stable sort, `indices[np.argsort(labels, kind="stable")]`), placed by counting:
    label l's voxels start at the sum of `sizes` (n,) before it."""
    start = np.empty(sizes.shape[0], dtype=np.int64)
    total = 0
    for lab in range(sizes.shape[0]):
        start[lab] = total
        total += sizes[lab]
    out = np.empty_like(indices)
    for p in range(indices.shape[0]):
        q = start[labels[p]]
        start[labels[p]] = q + 1
        out[q, 0] = indices[p, 0]
        out[q, 1] = indices[p, 1]
        out[q, 2] = indices[p, 2]
    return out


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

    Frontier voxels are a small share of the grid, and this runs at every call for clusters:
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


def _cell_keys(indices: IndexArray, labels: IndexArray, n: int, cell_voxels: float) -> IndexArray:
    """(K,) int64 key of the cell of its component each voxel falls in.

    Each component's bounding box is cut into the fewest equal cells at most `cell_voxels` wide
    per axis (one cell when the component already fits).

    indices: (K, 3) voxels; labels: (K,) component of each, in [0, n).
    """
    lo, hi = _label_boxes(indices, labels, n)
    extent = hi - lo + 1
    cells = np.maximum(np.ceil(extent / cell_voxels - 1e-9), 1).astype(np.int64)
    return _voxel_cell_keys(indices, labels, lo, extent, cells, int(np.prod(cells, axis=1).max()))


@numba.njit(cache=True)
def _voxel_cell_keys(indices: IndexArray, labels: IndexArray, lo: IndexArray, extent: IndexArray,
                     cells: IndexArray, stride: int) -> IndexArray:  # pragma: no cover - numba
    """Each voxel's key: its label times `stride` plus its cell's number within its label's box
    (cells[label] cells per axis over `extent[label]` voxels from `lo[label]`)."""
    keys = np.empty(indices.shape[0], np.int64)
    for p in range(indices.shape[0]):
        lab = labels[p]
        cx = (indices[p, 0] - lo[lab, 0]) * cells[lab, 0] // extent[lab, 0]
        cy = (indices[p, 1] - lo[lab, 1]) * cells[lab, 1] // extent[lab, 1]
        cz = (indices[p, 2] - lo[lab, 2]) * cells[lab, 2] // extent[lab, 2]
        keys[p] = lab * stride + (cx * cells[lab, 1] + cy) * cells[lab, 2] + cz
    return keys


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
        self._recompute(IndexBox.full(self._map.shape))

    def _recompute(self, region: IndexBox) -> None:
        lo, hi = region.lo, region.hi
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
        if self._count == 0:
            return []
        _, ny, nz = self._map.shape
        indices = _true_indices(self._bits, ny, nz, self._count)  # (F, 3), C order
        # The neighbour pairs are found once, joining the components as they are; the cells
        # then join along them.
        pairs, components, n = _pairs_and_components(indices, ny, nz)
        keys = _cell_keys(indices, components, n, max_extent_m / self._map.voxel_size)
        labels, n = _joined(pairs, keys, len(indices))

        sizes = np.bincount(labels, minlength=n)
        mean_dir, centre_sums = _label_sums(self._map.state, indices, labels, n,
                                            self._map.origin, self._map.voxel_size)
        centroid = centre_sums / sizes[:, None]
        norm = np.linalg.norm(mean_dir, axis=1)
        normal = np.zeros_like(mean_dir)
        nonzero = norm > 1e-12
        normal[nonzero] = mean_dir[nonzero] / norm[nonzero, None]

        grouped = _grouped(indices, labels, sizes)  # C order inside each piece
        grouped.setflags(write=False)
        ends = np.cumsum(sizes)
        result: list[FrontierCluster] = []
        # Only the kept pieces are cut out (most pieces are smaller than `min_size`).
        for label in np.flatnonzero(sizes >= min_size):
            piece = grouped[ends[label] - sizes[label]:ends[label]]
            result.append(
                FrontierCluster(
                    id=len(result),
                    indices=piece,
                    centroid=centroid[label],
                    normal=normal[label],
                    size=int(sizes[label]),
                )
            )
        return result
