"""Points listed by the cell of a uniform grid that holds them, for searches within a reach:
the points of a cell are `members[start[c]:start[c + 1]]`, cells numbered in C order."""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
import numpy.typing as npt

# The table is one int64 per cell over the points' bounds: a larger cell rather than a larger
# table past this many cells.
MAX_CELLS = 4_000_000


@dataclass(frozen=True)
class CellLists:
    """Attributes:
    origin: (3,) metres, the corner of cell (0, 0, 0); cell: edge, metres; shape: (3,) cells.
    start: (C + 1,) int64 offsets into `members`; members: (M,) int64 indices of the points.
    """

    origin: npt.NDArray[np.float64]
    cell: float
    shape: npt.NDArray[np.int64]
    start: npt.NDArray[np.int64]
    members: npt.NDArray[np.int64]


def cell_edge(low: npt.NDArray[np.float64], high: npt.NDArray[np.float64], wanted: float,
              margin_cells: int) -> float:
    """`wanted`, or larger so that the box low..high plus `margin_cells` cells on every side
    holds at most `MAX_CELLS` cells."""
    volume = float(np.prod(high - low + 2 * margin_cells * wanted))
    return max(wanted, (volume / MAX_CELLS) ** (1 / 3))


def cell_lists(points: npt.NDArray[np.float64], which: npt.NDArray[np.int64],
               low: npt.NDArray[np.float64], high: npt.NDArray[np.float64], cell: float,
               margin_cells: int) -> CellLists:
    """Lists `points[which]` by cell of edge `cell` over low..high grown by `margin_cells`
    cells (points outside are left out), in the order of `which` within each cell (a counting
    sort: beside the lists, one int64 per point and per cell for a moment)."""
    origin = low - margin_cells * cell
    shape = np.floor((high + margin_cells * cell - origin) / cell).astype(np.int64) + 1
    flat = _flat_cells(points, which, origin, cell, shape)
    start = _starts(flat, int(np.prod(shape)))
    return CellLists(origin, cell, shape, start, _members(flat, which, start))


@numba.njit(cache=True)
def _flat_cells(points: npt.NDArray[np.float64], which: npt.NDArray[np.int64],
                origin: npt.NDArray[np.float64], cell: float,
                shape: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:  # pragma: no cover
    """(len(which),) C-order number of each point's cell, -1 outside the grid."""
    flat = np.empty(which.shape[0], np.int64)
    for n in range(which.shape[0]):
        p = which[n]
        i = int(np.floor((points[p, 0] - origin[0]) / cell))
        j = int(np.floor((points[p, 1] - origin[1]) / cell))
        k = int(np.floor((points[p, 2] - origin[2]) / cell))
        if 0 <= i < shape[0] and 0 <= j < shape[1] and 0 <= k < shape[2]:
            flat[n] = (i * shape[1] + j) * shape[2] + k
        else:
            flat[n] = -1
    return flat


@numba.njit(cache=True)
def _members(flat: npt.NDArray[np.int64], which: npt.NDArray[np.int64],
             start: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:  # pragma: no cover
    """`which` grouped by cell, in their order within each cell."""
    members = np.empty(start[-1], np.int64)
    fill = start[:-1].copy()
    for n in range(flat.shape[0]):
        f = flat[n]
        if f >= 0:
            members[fill[f]] = which[n]
            fill[f] += 1
    return members


@numba.njit(cache=True)
def _starts(flat: npt.NDArray[np.int64], cells: int) -> npt.NDArray[np.int64]:  # pragma: no cover
    """(cells + 1,) offsets of each cell's points among the points inside the grid."""
    start = np.zeros(cells + 1, np.int64)
    for f in flat:
        if f >= 0:
            start[f + 1] += 1
    for c in range(cells):
        start[c + 1] += start[c]
    return start


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
    lists = cell_lists(qs, np.arange(len(qs)), low, high, cell, 1)
    near = np.zeros(len(qs), dtype=np.bool_)
    _mark_within(pts, qs, bound * bound, lists.origin, lists.cell, lists.shape, lists.start,
                 lists.members, near)
    return float(np.count_nonzero(near)) / len(qs)


@numba.njit(cache=True)
def _mark_within(points: npt.NDArray[np.float64], queries: npt.NDArray[np.float64],
                 bound2: float, origin: npt.NDArray[np.float64], cell: float,
                 shape: npt.NDArray[np.int64], start: npt.NDArray[np.int64],
                 members: npt.NDArray[np.int64],
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
