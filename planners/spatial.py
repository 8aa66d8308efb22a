"""A spatial index of points with values: past positions, cached viewpoint gains.

A grid hash: points go into cubic cells of `cell_m`; a radius query looks only at the cells the
ball overlaps. Unlike a k-d tree it takes insertions and removals one at a time, which is what a
planner adding a few nodes per iteration needs.
"""

from __future__ import annotations

import math
from collections import defaultdict

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
IdArray = npt.NDArray[np.int64]


class SpatialIndex:
    """Points (3,) with a value and a yaw each, by integer id.

    Args:
        cell_m: cell size of the hash; radius queries near this size are cheapest.
    """

    def __init__(self, cell_m: float = 1.0) -> None:
        if not cell_m > 0:
            raise ValueError(f"cell_m must be positive, got {cell_m}")
        self.cell_m = cell_m
        self._cells: defaultdict[tuple[int, int, int], list[int]] = defaultdict(list)
        self._points: list[FloatArray] = []
        self._values: list[float] = []
        self._yaws: list[float] = []
        self._alive: list[bool] = []
        self._count = 0

    def __len__(self) -> int:
        return self._count

    def _cell(self, p: FloatArray) -> tuple[int, int, int]:
        c = np.floor(p / self.cell_m).astype(np.int64)
        return int(c[0]), int(c[1]), int(c[2])

    def insert(self, point: npt.ArrayLike, value: float = 0.0, yaw: float = 0.0) -> int:
        """Add a point; returns its id."""
        p = np.asarray(point, dtype=np.float64).copy()
        ident = len(self._points)
        self._points.append(p)
        self._values.append(float(value))
        self._yaws.append(float(yaw))
        self._alive.append(True)
        self._cells[self._cell(p)].append(ident)
        self._count += 1
        return ident

    def remove(self, ident: int) -> None:
        if not self._alive[ident]:
            return
        self._alive[ident] = False
        self._cells[self._cell(self._points[ident])].remove(ident)
        self._count -= 1

    def update(self, ident: int, value: float, yaw: float | None = None) -> None:
        self._values[ident] = float(value)
        if yaw is not None:
            self._yaws[ident] = float(yaw)

    def point(self, ident: int) -> FloatArray:
        return self._points[ident]

    def value(self, ident: int) -> float:
        return self._values[ident]

    def yaw(self, ident: int) -> float:
        return self._yaws[ident]

    def within(self, point: npt.ArrayLike, radius: float) -> IdArray:
        """Ids of the points at most `radius` from `point`, ascending."""
        p = np.asarray(point, dtype=np.float64)
        lo = np.floor((p - radius) / self.cell_m).astype(np.int64)
        hi = np.floor((p + radius) / self.cell_m).astype(np.int64)
        found: list[int] = []
        for i in range(lo[0], hi[0] + 1):
            for j in range(lo[1], hi[1] + 1):
                for k in range(lo[2], hi[2] + 1):
                    found.extend(self._cells.get((i, j, k), ()))
        if not found:
            return np.zeros(0, dtype=np.int64)
        ids = np.array(sorted(found), dtype=np.int64)
        d = np.linalg.norm(np.array([self._points[n] for n in ids]) - p, axis=1)
        result: IdArray = ids[d <= radius]
        return result

    def nearest(self, point: npt.ArrayLike, max_radius: float = math.inf) -> int | None:
        """Id of the nearest point no farther than `max_radius` (lowest id on ties)."""
        if self._count == 0:
            return None
        p = np.asarray(point, dtype=np.float64)
        radius = self.cell_m
        while True:
            ids = self.within(p, min(radius, max_radius))
            if len(ids):
                d = np.linalg.norm(np.array([self._points[n] for n in ids]) - p, axis=1)
                best = int(ids[int(np.argmin(d))])
                # A point found within r is the nearest overall: anything nearer is within r.
                return best
            if radius >= max_radius:
                return None
            radius *= 2.0
            if radius > 1e6:
                return None

    def ids(self) -> IdArray:
        """Every live id, ascending."""
        return np.flatnonzero(np.array(self._alive, dtype=bool)).astype(np.int64)

    def points(self, ids: IdArray) -> FloatArray:
        """(len(ids), 3) positions."""
        if len(ids) == 0:
            return np.zeros((0, 3))
        return np.array([self._points[n] for n in ids])

    def values(self, ids: IdArray) -> FloatArray:
        return np.array([self._values[n] for n in ids], dtype=np.float64)
