"""A* path search on the traversable voxel grid, with a cache of recent paths.

Same graph as `planners.search.DistanceField` (26-connected, no corner cutting, steps weighted
by their length), so A* and Dijkstra find paths of equal length. The heuristic is the 3D octile
distance, the exact path length on an open grid: admissible and consistent, so the first time
the goal is popped its path is shortest.
"""

from __future__ import annotations

from collections import OrderedDict

import numba
import numpy as np
import numpy.typing as npt

from planners.search import (
    _OFFSETS,
    _STEP_COST,
    BoolGrid,
    IndexArray,
    _corner_free,
    _grown,
    _heap_pop,
    _heap_push,
    _new_heap,
    _workspace,
)

_SQRT2 = float(np.sqrt(2.0))
_SQRT3 = float(np.sqrt(3.0))


@numba.njit(cache=True)
def _octile(i: int, j: int, k: int, gi: int, gj: int, gk: int) -> float:
    a = abs(i - gi)
    b = abs(j - gj)
    c = abs(k - gk)
    hi = max(a, b, c)
    lo = min(a, b, c)
    mid = a + b + c - hi - lo
    return lo * _SQRT3 + (mid - lo) * _SQRT2 + (hi - mid)


@numba.njit(cache=True)
def _astar(
    passable: BoolGrid,
    start: IndexArray,
    goal: IndexArray,
    offsets: IndexArray,
    step_cost: npt.NDArray[np.float64],
    g: npt.NDArray[np.float64],
    parent: npt.NDArray[np.int64],
    done: npt.NDArray[np.bool_],
    touched: npt.NDArray[np.int64],
) -> tuple[IndexArray, float, npt.NDArray[np.int64], int]:
    """(K, 3) voxel path start → goal and its length in voxels; (0, 3) and inf if none.

    `g`, `parent` and `done` are clean flat workspaces (inf, -1, False), as for
    `planners.search.resume_search`; every voxel given a cost is listed in `touched` (returned,
    grown when full, with the count) for the caller to clean.
    """
    nx, ny, nz = passable.shape
    flat = passable.ravel()
    heap = _new_heap(1 << 14)
    gi, gj, gk = goal[0], goal[1], goal[2]
    s = (start[0] * ny + start[1]) * nz + start[2]
    target = (gi * ny + gj) * nz + gk
    g[s] = 0.0
    touched[0] = s
    n_touched = 1
    _heap_push(heap, 0, _octile(start[0], start[1], start[2], gi, gj, gk), s)
    size = 1
    found = False
    while size > 0:
        cur = int(heap[0, 1])
        size = _heap_pop(heap, size)
        if done[cur]:
            continue
        done[cur] = True
        if cur == target:
            found = True
            break
        # Room for every push and every newly touched voxel of this expansion (see
        # `planners.search`: no array is replaced inside the neighbour loop).
        if size + offsets.shape[0] > heap.shape[0]:
            heap = _grown(heap, size + offsets.shape[0])
        if n_touched + offsets.shape[0] > touched.shape[0]:
            touched = _grown(touched, n_touched + offsets.shape[0])
        ci = cur // (ny * nz)
        cj = (cur // nz) % ny
        ck = cur % nz
        g_cur = g[cur]
        for n in range(offsets.shape[0]):
            i = ci + offsets[n, 0]
            j = cj + offsets[n, 1]
            k = ck + offsets[n, 2]
            if i < 0 or j < 0 or k < 0 or i >= nx or j >= ny or k >= nz:
                continue
            idx = (i * ny + j) * nz + k
            if done[idx] or not flat[idx]:
                continue
            if not _corner_free(passable, ci, cj, ck, i, j, k):
                continue
            ng = g_cur + step_cost[n]
            if ng < g[idx]:
                if g[idx] == np.inf:
                    touched[n_touched] = idx
                    n_touched += 1
                g[idx] = ng
                parent[idx] = cur
                _heap_push(heap, size, ng + _octile(i, j, k, gi, gj, gk), idx)
                size += 1
    if not found:
        return np.zeros((0, 3), dtype=np.int64), np.inf, touched, n_touched
    count = 1
    p = target
    while parent[p] >= 0:
        p = parent[p]
        count += 1
    path = np.empty((count, 3), dtype=np.int64)
    p = target
    for r in range(count - 1, -1, -1):
        path[r, 0] = p // (ny * nz)
        path[r, 1] = (p // nz) % ny
        path[r, 2] = p % nz
        p = parent[p]
    return path, g[target], touched, n_touched


@numba.njit(cache=True)
def _chain_passable(passable: BoolGrid, path: IndexArray) -> bool:
    """Every voxel of a 26-neighbour chain is passable and no step cuts a corner."""
    for r in range(path.shape[0]):
        if not passable[path[r, 0], path[r, 1], path[r, 2]]:
            return False
    for r in range(1, path.shape[0]):
        if not _corner_free(passable, path[r - 1, 0], path[r - 1, 1], path[r - 1, 2],
                            path[r, 0], path[r, 1], path[r, 2]):
            return False
    return True


def astar(passable: BoolGrid, start: npt.ArrayLike, goal: npt.ArrayLike,
          voxel_size: float) -> tuple[IndexArray, float]:
    """Shortest 26-connected path through `passable` voxels.

    Returns:
        (K, 3) int64 voxel indices from start to goal (both included) and its length in
        metres; an empty (0, 3) path and inf when the goal cannot be reached.
    """
    s = np.asarray(start, dtype=np.int64)
    t = np.asarray(goal, dtype=np.int64)
    shape = np.array(passable.shape)
    for name, v in (("start", s), ("goal", t)):
        if v.shape != (3,) or np.any(v < 0) or np.any(v >= shape):
            raise ValueError(f"{name} {v.tolist()} is outside the grid {passable.shape}")
    if not (passable[tuple(s)] and passable[tuple(t)]):
        return np.zeros((0, 3), dtype=np.int64), np.inf
    # Reused clean buffers: a search costs what it visits, not three grid-sized allocations.
    ws = _workspace(int(passable.size))
    path, cost, ws.touched, count = _astar(passable, s, t, _OFFSETS, _STEP_COST, ws.dist,
                                           ws.parent, ws.done, ws.touched)
    ws.clean(ws.touched[:count])
    return path, float(cost) * voxel_size


class PathCache:
    """A* with a cache of found paths, keyed by (start, goal) voxels.

    A cached path is returned while it stays passable (the map only grows more known, so a
    still-passable path is at most as long as before, though a shorter one may have opened).
    Failures are not cached: the map may open a way at any time.

    Args:
        max_entries: least recently used paths beyond this are dropped.
    """

    def __init__(self, max_entries: int = 512) -> None:
        self.max_entries = max_entries
        self._paths: OrderedDict[tuple[int, ...], tuple[IndexArray, float]] = OrderedDict()
        self.hits = 0
        self.misses = 0

    def path(self, passable: BoolGrid, start: npt.ArrayLike, goal: npt.ArrayLike,
             voxel_size: float) -> tuple[IndexArray, float]:
        """Like `astar`, served from the cache when the cached path is still passable."""
        key = (*(int(v) for v in np.asarray(start)), *(int(v) for v in np.asarray(goal)))
        cached = self._paths.get(key)
        if cached is not None and _chain_passable(passable, cached[0]):
            self._paths.move_to_end(key)
            self.hits += 1
            return cached
        self.misses += 1
        path, cost = astar(passable, start, goal, voxel_size)
        if len(path):
            self._paths[key] = (path, cost)
            self._paths.move_to_end(key)
            while len(self._paths) > self.max_entries:
                self._paths.popitem(last=False)
        else:
            self._paths.pop(key, None)
        return path, cost

    def clear(self) -> None:
        self._paths.clear()
