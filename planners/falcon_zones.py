"""FALCON's connectivity-aware space decomposition (Zhang et al., T-RO 2024, Sec. IV; the public
code's `exploration_preprocessing/src/hierarchical_grid.cpp`), on the framework's map.

- **Cells**: a uniform grid of `cell_size_m` squares over the area (one layer of the area's full
  height for flat areas, the code's 2D grid; otherwise 2, 3 or 4 layers as the code splits
  boxes under 5, 10 and 20 m).
- **Zones**: in every cell, the connected components (26-connected, on a grid coarser by
  `ccl_step` voxels) of traversable space (free zones) and of unknown space (unknown zones).
  A coarse cell is free where any of its voxels is traversable and unknown where all are. Free
  zones need at least `min_free_cells` coarse cells, unknown zones `min_unknown_fraction` of the
  cell's coarse cells (`hgrid/min_unknown_num_scale`). Each zone's centre is the mean of its
  coarse cells, moved to the nearest of them (the code's nearest-neighbour snap).
- **Connectivity graph**: zones are nodes; free zones of adjacent cells whose coarse cells touch
  across the shared face are joined (the code's FREE edges), so are unknown zones (UNKNOWN
  edges), and a free zone joins the unknown zones of its own cell that lie within the
  vehicle's clearance of it (PORTAL edges; traversable space keeps that clearance from unknown
  space). Edge lengths are the distances between the zones' centres. Unknown zones in a
  connected part of the graph without a free zone are holes the vehicle cannot reach and are
  left out (the code's `findDisconnectedNodes`).

A cell is labelled again only when its coarse free and unknown cells changed (the code updates
the cells inside the map's updated box).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
import numpy.typing as npt
from scipy import ndimage, sparse
from scipy.sparse import csgraph

from planners.search import BoolGrid, IndexArray
from sim.map_view import MapView
from sim.occupancy import VoxelState

FloatArray = npt.NDArray[np.float64]

_CONNECT_26 = np.ones((3, 3, 3), dtype=bool)
_UNKNOWN = np.uint8(VoxelState.UNKNOWN)


@dataclass(frozen=True)
class _CellZones:
    """The zones of one cell: local labels (1..n, 0 outside any zone) over its coarse block."""

    labels: npt.NDArray[np.int32]
    unknown: npt.NDArray[np.bool_]  # (n,) kind of each local zone
    portals: IndexArray  # (P, 2) local (free, unknown) zone pairs
    centers: FloatArray  # (n, 3) coarse cell coordinates within the block


@dataclass(frozen=True)
class Zones:
    """The decomposition of one map.

    Attributes:
        centers: (N, 3) world metres.
        unknown: (N,) True for unknown zones, False for free zones.
        cell: (N,) index of the zone's cell.
        labels: coarse grid of zone ids + 1 (0: no zone).
        factor: voxels per coarse cell along each axis.
        graph: (N, N) sparse connectivity graph, edges as long as their centres are apart.
        kept: (N,) False for unknown zones that are holes.
    """

    centers: FloatArray
    unknown: npt.NDArray[np.bool_]
    cell: IndexArray
    labels: npt.NDArray[np.int32]
    factor: int
    graph: sparse.csr_matrix
    kept: npt.NDArray[np.bool_]

    def distance_m(self, a: IndexArray, b: IndexArray) -> FloatArray:
        """(A, B) shortest distances along the graph from zones `a` to zones `b` (inf: not
        joined), one Dijkstra search from each distinct zone of `a`."""
        if len(a) == 0 or len(b) == 0:
            return np.zeros((len(a), len(b)))
        sources, row = np.unique(a, return_inverse=True)
        dist = csgraph.dijkstra(self.graph, directed=False, indices=sources)
        out: FloatArray = dist[np.ix_(row.ravel(), b)]
        return out

    def zone_at(self, view: MapView, points: FloatArray) -> IndexArray:
        """(M,) the zone id holding each world point's coarse cell, -1 for none."""
        c = view.world_to_index(points) // self.factor
        c = np.clip(c, 0, np.array(self.labels.shape) - 1)
        out: IndexArray = self.labels[c[:, 0], c[:, 1], c[:, 2]].astype(np.int64) - 1
        return out


class ZoneGrid:
    """Cells over a map's grid and the zones of each, relabelled where the map changed."""

    def __init__(self, shape: tuple[int, int, int], origin: FloatArray, voxel_m: float,
                 cell_size_m: float, ccl_step: int, min_free_cells: int,
                 min_unknown_fraction: float, clearance_m: float,
                 layers: int | None = None) -> None:
        self.factor = ccl_step
        self.origin = np.asarray(origin, dtype=np.float64)
        self.voxel_m = voxel_m
        self.coarse_shape = tuple(math.ceil(n / ccl_step) for n in shape)
        coarse_m = voxel_m * ccl_step
        side = max(1, round(cell_size_m / coarse_m))
        height_m = shape[2] * voxel_m
        n_layers = layers if layers is not None else _layers(height_m)
        z_side = math.ceil(self.coarse_shape[2] / n_layers)
        self.sides = (side, side, z_side)
        self.counts = tuple(math.ceil(n / s) for n, s in zip(self.coarse_shape, self.sides,
                                                            strict=True))
        self.min_free_cells = min_free_cells
        self.min_unknown_fraction = min_unknown_fraction
        self.gap = max(1, math.ceil(clearance_m / coarse_m) + 1)
        self._cache: dict[bytes, _CellZones] = {}

    def cell_of(self, view: MapView, points: FloatArray) -> IndexArray:
        """(M,) the cell index of each world point."""
        c = view.world_to_index(points) // self.factor // np.array(self.sides)
        c = np.clip(c, 0, np.array(self.counts) - 1)
        out: IndexArray = (c[:, 0] * self.counts[1] + c[:, 1]) * self.counts[2] + c[:, 2]
        return out

    def _blocks(self) -> list[tuple[slice, slice, slice]]:
        sx, sy, sz = self.sides
        nx, ny, nz = self.counts
        return [(slice(i * sx, (i + 1) * sx), slice(j * sy, (j + 1) * sy),
                 slice(k * sz, (k + 1) * sz))
                for i in range(nx) for j in range(ny) for k in range(nz)]

    def update(self, view: MapView) -> Zones:
        """The zones of the current map."""
        f = self.factor
        free, unknown = _coarse(view.traversable, view.state, f)
        labels = np.zeros(self.coarse_shape, dtype=np.int32)
        kinds: list[npt.NDArray[np.bool_]] = []
        cells: list[IndexArray] = []
        portals: list[IndexArray] = []
        corners: list[FloatArray] = []
        kept: dict[bytes, _CellZones] = {}
        offset = 0
        for index, block in enumerate(self._blocks()):
            fb, ub = free[block], unknown[block]
            key = np.packbits(fb).tobytes() + np.packbits(ub).tobytes()
            zones = self._cache.get(key) or kept.get(key) or self._label(fb, ub)
            kept[key] = zones
            n = len(zones.unknown)
            if n == 0:
                continue
            local = zones.labels
            labels[block] = np.where(local > 0, local + offset, 0)
            kinds.append(zones.unknown)
            cells.append(np.full(n, index, dtype=np.int64))
            portals.append(zones.portals + offset)
            corners.append(zones.centers + np.array([b.start for b in block]))
            offset += n
        self._cache = kept
        unknown_kind = np.concatenate(kinds) if kinds else np.zeros(0, dtype=bool)
        cell = np.concatenate(cells) if cells else np.zeros(0, dtype=np.int64)
        f_m = self.factor * self.voxel_m
        centers = (self.origin + (np.vstack(corners) + 0.5) * f_m if corners
                   else np.zeros((0, 3)))
        edges = np.vstack([self._face_pairs(labels, unknown_kind), *portals]
                          ) if offset else np.zeros((0, 2), dtype=np.int64)
        graph = _graph(centers, edges, offset)
        return Zones(centers, unknown_kind, cell, labels, f, graph, _not_holes(graph, unknown_kind))

    def _label(self, free: BoolGrid, unknown: BoolGrid) -> _CellZones:
        """Zones of one cell's coarse block (see the module's docstring)."""
        out = np.zeros(free.shape, dtype=np.int32)
        kinds: list[bool] = []
        min_unknown = self.min_unknown_fraction * free.size
        for is_unknown, mask, least in ((False, free, self.min_free_cells),
                                        (True, unknown, min_unknown)):
            lab, n = ndimage.label(mask, structure=_CONNECT_26)
            if n == 0:
                continue
            sizes = np.bincount(lab.ravel(), minlength=n + 1)
            big = np.flatnonzero(sizes[1:] >= least) + 1
            remap = np.zeros(n + 1, dtype=np.int32)
            remap[big] = len(kinds) + 1 + np.arange(len(big), dtype=np.int32)
            out = np.where(remap[lab] > 0, remap[lab], out)
            kinds.extend([is_unknown] * len(big))
        kind = np.array(kinds, dtype=bool)
        return _CellZones(out, kind, self._portals(out, kind), _centers(out, len(kind)))

    def _portals(self, labels: npt.NDArray[np.int32],
                 unknown: npt.NDArray[np.bool_]) -> IndexArray:
        """Local (free, unknown) zone pairs within `gap` coarse cells of each other."""
        if not unknown.any() or unknown.all():
            return np.zeros((0, 2), dtype=np.int64)
        is_unknown = np.concatenate([[False], unknown])[labels]
        ulab = np.where(is_unknown, labels, 0)
        size = 2 * self.gap + 1
        near_max = ndimage.maximum_filter(ulab, size=size, mode="constant")
        big = np.iinfo(np.int32).max
        near_min = ndimage.minimum_filter(np.where(ulab > 0, ulab, big), size=size,
                                          mode="constant", cval=big)
        free_cells = (labels > 0) & ~is_unknown
        pairs = np.concatenate([
            np.stack([labels[free_cells], near[free_cells]], axis=1)
            for near in (near_max, near_min)])
        pairs = pairs[(pairs[:, 1] > 0) & (pairs[:, 1] < big)]
        out: IndexArray = np.unique(pairs, axis=0).astype(np.int64) - 1
        return out

    def _face_pairs(self, labels: npt.NDArray[np.int32],
                    unknown: npt.NDArray[np.bool_]) -> IndexArray:
        """Zone pairs of the same kind whose coarse cells touch across a cell face."""
        n = len(unknown)
        codes = [np.zeros(0, dtype=np.int64)]
        for axis, side in enumerate(self.sides):
            at = np.arange(side, labels.shape[axis], side)
            if len(at) == 0:
                continue
            a = labels.take(at - 1, axis=axis).ravel().astype(np.int64)
            c = labels.take(at, axis=axis).ravel().astype(np.int64)
            ok = (a > 0) & (c > 0)
            a, c = a[ok] - 1, c[ok] - 1
            same = unknown[a] == unknown[c]
            codes.append(a[same] * n + c[same])
        found = np.unique(np.concatenate(codes))
        out: IndexArray = np.stack([found // n, found % n], axis=1)
        return out


def _centers(labels: npt.NDArray[np.int32], n: int) -> FloatArray:
    """(n, 3) each zone's coarse cell nearest the mean of its cells (coarse coordinates)."""
    if n == 0:
        return np.zeros((0, 3))
    cells = np.argwhere(labels).astype(np.float64)
    ids = labels[labels > 0].astype(np.int64) - 1  # argwhere's order: C order, as this
    counts = np.bincount(ids, minlength=n).astype(np.float64)
    sums = np.stack([np.bincount(ids, cells[:, a], n) for a in range(3)], axis=1)
    mean = sums / np.maximum(counts, 1.0)[:, None]
    dist = np.sum((cells - mean[ids]) ** 2, axis=1)
    order = np.lexsort((dist, ids))
    first = order[np.searchsorted(ids[order], np.arange(n))]
    out: FloatArray = cells[first]
    return out


def _layers(height_m: float) -> int:
    """The code's layers: one for boxes up to 2 m high (its 2D grids), then 2, 3 or 4 below 5,
    10 and 20 m."""
    if height_m <= 2.0 + 1e-6:
        return 1
    for layers, below in ((2, 5.0), (3, 10.0), (4, 20.0)):
        if height_m < below:
            return layers
    return max(1, round(height_m / 5.0))


@numba.njit(cache=True)
def _coarse(traversable: BoolGrid, state: npt.NDArray[np.uint8],
            f: int) -> tuple[BoolGrid, BoolGrid]:
    """Coarse grids of `f`-voxel cubes: free where any voxel is traversable, unknown where every
    voxel is unknown (cubes past the grid's end count their missing voxels as unknown)."""
    nx, ny, nz = traversable.shape
    cx, cy, cz = (nx + f - 1) // f, (ny + f - 1) // f, (nz + f - 1) // f
    free = np.zeros((cx, cy, cz), dtype=np.bool_)
    unknown = np.ones((cx, cy, cz), dtype=np.bool_)
    for a in range(cx):
        for b in range(cy):
            for c in range(cz):
                # Stop scanning a cube once both answers are known.
                for i in range(a * f, min(a * f + f, nx)):
                    for j in range(b * f, min(b * f + f, ny)):
                        for k in range(c * f, min(c * f + f, nz)):
                            if traversable[i, j, k]:
                                free[a, b, c] = True
                            if state[i, j, k] != _UNKNOWN:
                                unknown[a, b, c] = False
                            if free[a, b, c] and not unknown[a, b, c]:
                                break
    return free, unknown


def _graph(centers: FloatArray, edges: IndexArray, n: int) -> sparse.csr_matrix:
    """(n, n) the edges, each as long as its centres are apart."""
    length = np.linalg.norm(centers[edges[:, 0]] - centers[edges[:, 1]], axis=1)
    return sparse.coo_matrix((np.maximum(length, 1e-3), (edges[:, 0], edges[:, 1])),
                             shape=(n, n)).tocsr()


def _not_holes(graph: sparse.csr_matrix, unknown: npt.NDArray[np.bool_]) -> npt.NDArray[np.bool_]:
    """(n,) False for unknown zones in a connected part of the graph without a free zone."""
    if len(unknown) == 0:
        return np.zeros(0, dtype=bool)
    _, part = csgraph.connected_components(graph, directed=False)
    with_free = np.zeros(part.max() + 1, dtype=bool)
    with_free[part[~unknown]] = True
    out: npt.NDArray[np.bool_] = with_free[part]
    return out
