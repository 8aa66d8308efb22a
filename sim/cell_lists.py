"""Points listed by the cell of a uniform grid that holds them, for searches within a reach:
the points of a cell are `members[start[c]:start[c + 1]]`, cells numbered in C order."""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
import numpy.typing as npt

# The table is one int32 per cell over the points' bounds: a larger cell rather than a larger
# table past this many cells.
MAX_CELLS = 4_000_000


@dataclass(frozen=True)
class CellLists:
    """Attributes:
    origin: (3,) metres, the corner of cell (0, 0, 0); cell: edge, metres; shape: (3,) cells.
    start: (C + 1,) offsets into `members`, int32 (int64 past 2^31 - 1 points); members: (M,)
        indices of the points (the dtype of those listed).
    """

    origin: npt.NDArray[np.float64]
    cell: float
    shape: npt.NDArray[np.int64]
    start: npt.NDArray[np.integer]
    members: npt.NDArray[np.integer]


def cell_edge(low: npt.NDArray[np.float64], high: npt.NDArray[np.float64], wanted: float,
              margin_cells: int) -> float:
    """`wanted`, or larger so that the box low..high plus `margin_cells` cells on every side
    holds at most `MAX_CELLS` cells."""
    volume = float(np.prod(high - low + 2 * margin_cells * wanted))
    return max(wanted, (volume / MAX_CELLS) ** (1 / 3))


def cell_lists(points: npt.NDArray[np.float64], which: npt.NDArray[np.integer],
               low: npt.NDArray[np.float64], high: npt.NDArray[np.float64], cell: float,
               margin_cells: int) -> CellLists:
    """Lists `points[which]` by cell of edge `cell` over low..high grown by `margin_cells`
    cells (points outside are left out), in the order of `which` within each cell: a counting
    sort that holds nothing beside the lists."""
    origin = low - margin_cells * cell
    shape = np.floor((high + margin_cells * cell - origin) / cell).astype(np.int64) + 1
    # int32 offsets: 16 MiB less beside millions of points at the run's memory peak.
    start: npt.NDArray[np.integer] = np.zeros(
        int(np.prod(shape)) + 1, np.int32 if len(which) < 2**31 else np.int64)
    _count(points, which, origin, cell, shape, start)
    members = np.empty(int(start[-1]), dtype=which.dtype)
    _fill(points, which, origin, cell, shape, start, members)
    return CellLists(origin, cell, shape, start, members)


@numba.njit(cache=True)
def _cell_of(points: npt.NDArray[np.float64], p: int, origin: npt.NDArray[np.float64],
             cell: float, shape: npt.NDArray[np.int64]) -> int:  # pragma: no cover - numba
    """The C-order number of point p's cell, -1 outside the grid."""
    i = int(np.floor((points[p, 0] - origin[0]) / cell))
    j = int(np.floor((points[p, 1] - origin[1]) / cell))
    k = int(np.floor((points[p, 2] - origin[2]) / cell))
    if 0 <= i < shape[0] and 0 <= j < shape[1] and 0 <= k < shape[2]:
        return (i * shape[1] + j) * shape[2] + k
    return -1


@numba.njit(cache=True)
def _count(points: npt.NDArray[np.float64], which: npt.NDArray[np.integer],
           origin: npt.NDArray[np.float64], cell: float, shape: npt.NDArray[np.int64],
           start: npt.NDArray[np.integer]) -> None:  # pragma: no cover - numba
    """Fills `start` (cells + 1, zeros) with the offset of each cell's points."""
    for n in range(which.shape[0]):
        f = _cell_of(points, which[n], origin, cell, shape)
        if f >= 0:
            start[f + 1] += 1
    for c in range(start.shape[0] - 1):
        start[c + 1] += start[c]


@numba.njit(cache=True)
def _fill(points: npt.NDArray[np.float64], which: npt.NDArray[np.integer],
          origin: npt.NDArray[np.float64], cell: float, shape: npt.NDArray[np.int64],
          start: npt.NDArray[np.integer],
          members: npt.NDArray[np.integer]) -> None:  # pragma: no cover - numba
    """Writes `which` into `members` by cell, using `start` as each cell's next slot, then
    moves `start` back (each cell's next slot ends as the next cell's start)."""
    for n in range(which.shape[0]):
        f = _cell_of(points, which[n], origin, cell, shape)
        if f >= 0:
            members[start[f]] = which[n]
            start[f] += 1
    for c in range(start.shape[0] - 1, 0, -1):
        start[c] = start[c - 1]
    start[0] = 0


def share_within(points: npt.ArrayLike, queries: npt.ArrayLike, bound: float) -> float:
    """Share of `queries` (N, 3) with one of `points` (M, 3) at a distance below `bound`
    (squared distances compared, summed x, y, z). The queries are listed by cell and each point
    marks those near it, so the lists hold the (usually fewer) queries, not the points."""
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    qs = np.ascontiguousarray(queries, dtype=np.float64).reshape(-1, 3)
    if len(qs) == 0 or len(pts) == 0:
        return 0.0
    low, high = qs.min(axis=0), qs.max(axis=0)
    cell = cell_edge(low, high, bound, 1)
    lists = cell_lists(qs, np.arange(len(qs), dtype=np.int32), low, high, cell, 1)
    near = np.zeros(len(qs), dtype=np.bool_)
    _mark_within(pts, qs, bound * bound, lists.origin, lists.cell, lists.shape, lists.start,
                 lists.members, near)
    return float(np.count_nonzero(near)) / len(qs)


@numba.njit(cache=True)
def _mark_within(points: npt.NDArray[np.float64], queries: npt.NDArray[np.float64],
                 bound2: float, origin: npt.NDArray[np.float64], cell: float,
                 shape: npt.NDArray[np.int64], start: npt.NDArray[np.integer],
                 members: npt.NDArray[np.integer],
                 near: npt.NDArray[np.bool_]) -> None:  # pragma: no cover - numba
    """Sets `near` on the queries at squared distance below `bound2` from a point (cells at
    least the bound: the cells around a point's own one hold every such query)."""
    for p in range(points.shape[0]):
        px, py, pz = points[p, 0], points[p, 1], points[p, 2]
        cx = int(np.floor((px - origin[0]) / cell))
        cy = int(np.floor((py - origin[1]) / cell))
        cz = int(np.floor((pz - origin[2]) / cell))
        for i in range(max(cx - 1, 0), min(cx + 1, shape[0] - 1) + 1):
            for j in range(max(cy - 1, 0), min(cy + 1, shape[1] - 1) + 1):
                row = (i * shape[1] + j) * shape[2]
                for k in range(max(cz - 1, 0), min(cz + 1, shape[2] - 1) + 1):
                    for s in range(start[row + k], start[row + k + 1]):
                        q = members[s]
                        if near[q]:
                            continue
                        dx = queries[q, 0] - px
                        dy = queries[q, 1] - py
                        dz = queries[q, 2] - pz
                        if dx * dx + dy * dy + dz * dz < bound2:
                            near[q] = True
