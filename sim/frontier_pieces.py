"""The frontier's pieces: its 26-connected components, each cut into cells at most a given
width, with each piece's voxels, centroid and normal; and how to keep them from one call to the
next, computing again only the components the map's changes may have touched.

A component whose box, grown by one voxel, misses every voxel whose frontier state was
recomputed since the pieces were made is the same component: none of its voxels changed (they
lie outside that region), no new frontier voxel touches it (one would lie within its grown box),
and its voxels' unknown 6-neighbours are unchanged (the recomputed region holds every changed
voxel grown by one). Its cells (cut from its box) and pieces are then the same too, and so are
their sums, added over the same voxels in the same C order. The frontier's other voxels form
whole components of their own, computed as from scratch; the two sets together are every
component, their pieces numbered again by their first voxel in C order: what a computation of
the whole frontier gives, to the bit (`tests/sim/test_frontiers.py`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
import numpy.typing as npt

from sim.geometry import FloatArray
from sim.occupancy import IndexArray, IndexBox, StateGrid, VoxelState

_UNKNOWN = np.uint8(VoxelState.UNKNOWN)


@dataclass(frozen=True, eq=False)
class Pieces:
    """The pieces of a set of whole frontier components (arrays read-only once made).

    Attributes:
        cell_voxels: the widest a piece may be, in voxels (the cut they were made with).
        comp_lo, comp_hi: (C, 3) int64 inclusive voxel box of each component (after `merged`,
            components are in no particular order).
        grouped: (F, 3) int64 the voxels, piece after piece, each piece in C order.
        start, size: (P,) int64 each piece's rows in `grouped`; pieces in C order of their
            first voxel.
        first: (P,) int64 flat index of each piece's first voxel.
        comp: (P,) int64 each piece's component.
        centroid: (P, 3) float64 world metres; normal: (P, 3) float64 (`FrontierCluster`).
    """

    cell_voxels: float
    comp_lo: IndexArray
    comp_hi: IndexArray
    grouped: IndexArray
    start: IndexArray
    size: IndexArray
    first: IndexArray
    comp: IndexArray
    centroid: FloatArray
    normal: FloatArray


def pieces_of(indices: IndexArray, shape: tuple[int, int, int], state: StateGrid,
              origin: FloatArray, voxel_size: float, cell_voxels: float) -> Pieces:
    """The pieces of the voxels `indices` (K, 3) int64, distinct, in C order, whole components
    of the frontier of `state` ((nx, ny, nz) `VoxelState`) on a grid of `origin` (3,) and
    `voxel_size` metres."""
    _, ny, nz = shape
    if len(indices) == 0:
        none = np.zeros(0, dtype=np.int64)
        boxes = np.zeros((0, 3), dtype=np.int64)
        return _frozen(Pieces(cell_voxels, boxes, boxes.copy(), boxes.copy(), none, none.copy(),
                              none.copy(), none.copy(), np.zeros((0, 3)), np.zeros((0, 3))))
    # The neighbour pairs are found once, joining the components as they are; the cells then
    # join along them.
    pairs, components, n_comp = _pairs_and_components(indices, ny, nz)
    comp_lo, comp_hi = _label_boxes(indices, components, n_comp)
    keys = _cell_keys(indices, components, comp_lo, comp_hi, cell_voxels)
    labels, n = _joined(pairs, keys, len(indices))
    sizes = np.bincount(labels, minlength=n)
    mean_dir, centre_sums = _label_sums(state, indices, labels, n, origin, voxel_size)
    centroid = centre_sums / sizes[:, None]
    norm = np.linalg.norm(mean_dir, axis=1)
    normal = np.zeros_like(mean_dir)
    nonzero = norm > 1e-12
    normal[nonzero] = mean_dir[nonzero] / norm[nonzero, None]
    grouped = _grouped(indices, labels, sizes)  # C order inside each piece
    start = np.cumsum(sizes) - sizes
    heads = grouped[start]
    first = (heads[:, 0] * ny + heads[:, 1]) * nz + heads[:, 2]
    # A piece lies in one component: every voxel of a label gives it the same one.
    comp = np.empty(n, dtype=np.int64)
    comp[labels] = components
    return _frozen(Pieces(cell_voxels, comp_lo, comp_hi, grouped, start, sizes, first, comp,
                          centroid, normal))


def touched_components(pieces: Pieces, region: IndexBox) -> npt.NDArray[np.bool_]:
    """(C,) whether each component's box grown by one voxel meets the half-open `region`."""
    lo = np.asarray(region.lo, dtype=np.int64)
    hi = np.asarray(region.hi, dtype=np.int64)
    return np.all((pieces.comp_lo - 1 < hi) & (pieces.comp_hi + 1 >= lo), axis=1)


def merged(kept_from: Pieces, kept: npt.NDArray[np.bool_], new: Pieces) -> Pieces:
    """The pieces of `kept_from`'s components marked in `kept` (C,) with those of `new` (other
    whole components), numbered again by their first voxel."""
    renumber = np.cumsum(kept) - 1
    offset = int(np.count_nonzero(kept))
    old_pieces = kept[kept_from.comp]
    first = np.concatenate([kept_from.first[old_pieces], new.first])
    order = np.argsort(first, kind="stable")  # distinct first voxels: any sort gives the order
    size = np.concatenate([kept_from.size[old_pieces], new.size])[order]
    source_start = np.concatenate([kept_from.start[old_pieces],
                                   new.start + len(kept_from.grouped)])[order]
    grouped = _rows(np.concatenate([kept_from.grouped, new.grouped]), source_start, size)
    return _frozen(Pieces(
        kept_from.cell_voxels,
        np.concatenate([kept_from.comp_lo[kept], new.comp_lo]),
        np.concatenate([kept_from.comp_hi[kept], new.comp_hi]),
        grouped,
        np.cumsum(size) - size,
        size,
        first[order],
        np.concatenate([renumber[kept_from.comp[old_pieces]], new.comp + offset])[order],
        np.concatenate([kept_from.centroid[old_pieces], new.centroid])[order],
        np.concatenate([kept_from.normal[old_pieces], new.normal])[order],
    ))


def _frozen(pieces: Pieces) -> Pieces:
    """`pieces` with every array read-only: clusters hand out views of them, and the pieces
    are kept for the next call."""
    for value in vars(pieces).values():
        if isinstance(value, np.ndarray):
            value.setflags(write=False)
    return pieces


def clear_kept(bits: npt.NDArray[np.uint64], pieces: Pieces, kept: npt.NDArray[np.bool_],
               ny: int, nz: int) -> int:
    """Clear in `bits` (one bit per voxel of a (.., ny, nz) grid: word v >> 6, bit v & 63 of
    flat index v) the voxels of the components marked in `kept` (C,); returns how many bits
    were set."""
    return _clear_rows(bits, pieces.grouped, pieces.start, pieces.size, kept[pieces.comp], ny, nz)


@numba.njit(cache=True)
def _clear_rows(bits: npt.NDArray[np.uint64], grouped: IndexArray, start: IndexArray,
                size: IndexArray, chosen: npt.NDArray[np.bool_], ny: int, nz: int) -> int:
    """Clear the bits of the voxels of the `chosen` (P,) pieces (rows of `grouped`)."""
    cleared = 0
    for p in range(start.shape[0]):
        if not chosen[p]:
            continue
        for r in range(start[p], start[p] + size[p]):
            v = (grouped[r, 0] * ny + grouped[r, 1]) * nz + grouped[r, 2]
            bit = np.uint64(1) << np.uint64(v & 63)
            if bits[v >> 6] & bit:
                bits[v >> 6] ^= bit
                cleared += 1
    return cleared


@numba.njit(cache=True)
def _rows(source: IndexArray, start: IndexArray, size: IndexArray) -> IndexArray:
    """(sum(size), 3) the rows start[i] .. start[i] + size[i] of `source` (M, 3), i in order."""
    out = np.empty((np.sum(size), 3), dtype=np.int64)
    q = 0
    for i in range(start.shape[0]):
        for r in range(start[i], start[i] + size[i]):
            out[q, 0] = source[r, 0]
            out[q, 1] = source[r, 1]
            out[q, 2] = source[r, 2]
            q += 1
    return out


@numba.njit(cache=True)
def unknown_directions(state: StateGrid, indices: IndexArray) -> FloatArray:
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
    """Per label, the (n, 3) sums of its voxels' `unknown_directions` and of their centres
    (world: origin + (index + 0.5) * voxel_size), added in the order of `indices` (K, 3); one
    pass instead of a grid of directions and centres and six weighted counts."""
    directions = unknown_directions(state, indices)
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


def _cell_keys(indices: IndexArray, labels: IndexArray, lo: IndexArray, hi: IndexArray,
               cell_voxels: float) -> IndexArray:
    """(K,) int64 key of the cell of its component each voxel falls in.

    Each component's bounding box is cut into the fewest equal cells at most `cell_voxels` wide
    per axis (one cell when the component already fits).

    indices: (K, 3) voxels; labels: (K,) component of each; lo, hi: (n, 3) each component's
    inclusive box (`_label_boxes`).
    """
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
