"""Shared path search on the voxel grid: Dijkstra distance fields, paths and straight-line checks.

All functions take voxel indices (i, j, k) on the map's grid and the grid's boolean masks, so
any planner can reuse them with its own notion of where the vehicle may fly.
"""

from __future__ import annotations

import threading
from abc import ABC, abstractmethod
from collections.abc import Callable
from functools import cached_property
from typing import Any

import numba
import numpy as np
import numpy.typing as npt

from sim.search_checks import segment_in_mask

BoolGrid = npt.NDArray[np.bool_]
IndexArray = npt.NDArray[np.int64]

# 26-neighbourhood offsets and their lengths in voxels.
_OFFSETS = np.array(
    [(di, dj, dk) for di in (-1, 0, 1) for dj in (-1, 0, 1) for dk in (-1, 0, 1)
     if (di, dj, dk) != (0, 0, 0)],
    dtype=np.int64,
)
_STEP_COST = np.sqrt(np.sum(_OFFSETS**2, axis=1)).astype(np.float64)


# A search's priority queue: a binary min-heap of (key, voxel) rows in one (M, 2) float64 array,
# the flat voxel index stored as a float (exact below 2^53), so that each level of a sift reads
# one cache line rather than one in each of two arrays. Ties pop in the order of the classic
# swap-based heap: the hole-moving sifts below make the same moves. A search makes room once per
# expanded voxel (`_grown` when fewer than 26 rows are free) and pushes without a check: an
# array that a push may replace is reloaded, and its reference counted, at every push, which
# cost a fifth of a large search.
HeapArray = npt.NDArray[np.float64]


@numba.njit(cache=True)
def _new_heap(rows: int) -> HeapArray:
    return np.empty((rows, 2), dtype=np.float64)


@numba.njit(cache=True)
def _grown(a: npt.NDArray[Any], rows: int) -> npt.NDArray[Any]:
    """`a` followed by uninitialised rows, doubled until it has at least `rows` rows."""
    while a.shape[0] < rows:
        a = np.concatenate((a, np.empty_like(a)))
    return a


@numba.njit(cache=True)
def _heap_push(heap: HeapArray, size: int, key: float, val: int) -> None:
    """Push (key, val) into a heap with room for it (size < rows); the size grows by one."""
    i = size
    while i > 0:
        p = (i - 1) >> 1
        if heap[p, 0] <= key:
            break
        heap[i, 0] = heap[p, 0]
        heap[i, 1] = heap[p, 1]
        i = p
    heap[i, 0] = key
    heap[i, 1] = val


@numba.njit(cache=True)
def _heap_pop(heap: HeapArray, size: int) -> int:
    """Drop the top row (read it first); returns the new size."""
    size -= 1
    key = heap[size, 0]
    val = heap[size, 1]
    i = 0
    while True:
        left = 2 * i + 1
        if left >= size:
            break
        c = left
        if left + 1 < size and heap[left + 1, 0] < heap[left, 0]:
            c = left + 1
        if key <= heap[c, 0]:
            break
        heap[i, 0] = heap[c, 0]
        heap[i, 1] = heap[c, 1]
        i = c
    heap[i, 0] = key
    heap[i, 1] = val
    return size


@numba.njit(cache=True)
def _corner_free(passable: BoolGrid, ci: int, cj: int, ck: int, i: int, j: int, k: int) -> bool:
    """A diagonal step may not cut a corner: every voxel of the cube it spans must be passable,
    so that the straight segment between the two centres stays in passable voxels."""
    for a in (ci, i):
        for b in (cj, j):
            for c in (ck, k):
                if not passable[a, b, c]:
                    return False
    return True


@numba.njit(cache=True)
def resume_search(
    passable: BoolGrid,
    goals: BoolGrid,
    max_cost: float,
    dist: npt.NDArray[np.float64],
    parent: npt.NDArray[np.int64],
    done: npt.NDArray[np.bool_],
    touched: npt.NDArray[np.int64],
    n_touched: int,
    heap: HeapArray,
    size: int,
    expand: int,
) -> tuple[int, npt.NDArray[np.int64], int, HeapArray, int]:
    """Runs a search on, over the 26-neighbourhood, until the first popped voxel set in `goals`
    (returned as a flat index, -1 if none) or until the frontier passes `max_cost` (voxels).
    A `CompiledAccept` calls it from its own compiled code.

    `dist`, `parent` and `done` are flat workspaces over the grid (inf, -1, False where the search
    has not been); the search writes its results there and lists every voxel it gave a distance
    in `touched[:n_touched]` (grown when full), so that the caller can read and clean up only
    those instead of the whole grid. `heap` and `size` are its queue (grown when full).
    `expand`, when not -1, is the goal the previous call returned and the caller turned down: it
    is expanded first, as if it had not been a goal. Returns the goal, then the arrays in use
    with their counts, to continue from.
    """
    nx, ny, nz = passable.shape
    flat_passable = passable.ravel()
    flat_goals = goals.ravel()
    offsets, step_cost = _OFFSETS, _STEP_COST
    resuming = expand >= 0
    cur = expand
    d = dist[expand] if resuming else 0.0
    while resuming or size > 0:
        if resuming:
            resuming = False
        else:
            d = heap[0, 0]
            cur = int(heap[0, 1])
            size = _heap_pop(heap, size)
            if done[cur]:
                continue
            if d > max_cost:
                break
            done[cur] = True
            if flat_goals[cur]:
                return cur, touched, n_touched, heap, size
        # Room for every push and every newly touched voxel of this expansion.
        if size + offsets.shape[0] > heap.shape[0]:
            heap = _grown(heap, size + offsets.shape[0])
        if n_touched + offsets.shape[0] > touched.shape[0]:
            touched = _grown(touched, n_touched + offsets.shape[0])
        ci = cur // (ny * nz)
        cj = (cur // nz) % ny
        ck = cur % nz
        for n in range(offsets.shape[0]):
            i = ci + offsets[n, 0]
            j = cj + offsets[n, 1]
            k = ck + offsets[n, 2]
            if i < 0 or j < 0 or k < 0 or i >= nx or j >= ny or k >= nz:
                continue
            idx = (i * ny + j) * nz + k
            if done[idx] or not flat_passable[idx]:
                continue
            if not _corner_free(passable, ci, cj, ck, i, j, k):
                continue
            nd = d + step_cost[n]
            if nd < dist[idx]:
                if dist[idx] == np.inf:
                    touched[n_touched] = idx
                    n_touched += 1
                dist[idx] = nd
                parent[idx] = cur
                _heap_push(heap, size, nd, idx)
                size += 1
    return -1, touched, n_touched, heap, size


class CompiledAccept(ABC):
    """A goal test that runs inside the compiled search, for `DistanceField(accept=...)`.

    A Python callable is asked once for every goal the search reaches and turns down; where
    that happens hundreds of times a search, the return to Python for each costs more than the
    test. A `CompiledAccept` runs the search itself, in compiled code, and stops at the first
    goal it accepts: the same voxels in the same order as the callable would give.
    """

    @abstractmethod
    def search_on(
        self, passable: BoolGrid, goals: BoolGrid, max_cost: float,
        dist: npt.NDArray[np.float64], parent: npt.NDArray[np.int64],
        done: npt.NDArray[np.bool_], touched: npt.NDArray[np.int64], n_touched: int,
        heap: HeapArray, size: int,
    ) -> tuple[int, npt.NDArray[np.int64], int, HeapArray, int]:
        """Call `resume_search` with these arguments, `expand` -1 at first and then each goal
        turned down, until it returns a goal this test accepts or -1; return its answer."""


class _Workspace:
    """Flat buffers over one grid, reused by every search in a thread and clean between them:
    a search then costs what it visits, not the grid's size (allocating and filling three
    grid-sized arrays per call cost more than most searches, and several times more where fresh
    pages are expensive, as in the planner sandbox)."""

    def __init__(self, size: int) -> None:
        self.size = size
        self.dist = np.full(size, np.inf, dtype=np.float64)
        self.parent = np.full(size, -1, dtype=np.int64)
        self.done = np.zeros(size, dtype=np.bool_)
        self.touched = np.empty(1 << 12, dtype=np.int64)

    def clean(self, visited: npt.NDArray[np.int64]) -> None:
        """Reset the voxels a search listed as visited, for the next search."""
        self.dist[visited] = np.inf
        self.parent[visited] = -1
        self.done[visited] = False


_WORKSPACES = threading.local()


def _workspace(size: int) -> _Workspace:
    ws: _Workspace | None = getattr(_WORKSPACES, "current", None)
    if ws is None or ws.size != size:
        ws = _WORKSPACES.current = _Workspace(size)
    return ws


class DistanceField:
    """Shortest path lengths (metres) from one voxel through passable voxels, 26-connected.

    With `goals`, the search stops at the nearest goal voxel (`nearest_goal`); distances are then
    final only for voxels no farther than that goal. With `accept` as well, a goal voxel is one
    only if `accept(voxel)` says so, asked as the search reaches it, nearest first: a test too
    costly to run on every goal ahead of the search is run on those nearer than the answer
    (`accept` a `CompiledAccept`: the same, asked from compiled code). Results are kept for
    the visited voxels only; `dist_m` expands them to a grid when asked.
    """

    def __init__(
        self,
        passable: BoolGrid,
        start: npt.ArrayLike,
        voxel_size: float,
        *,
        goals: BoolGrid | None = None,
        accept: Callable[[IndexArray], bool] | CompiledAccept | None = None,
        max_cost_m: float = np.inf,
    ) -> None:
        self.shape = passable.shape
        self.start = np.asarray(start, dtype=np.int64)
        # The compiled search does no bounds checks: refuse what would read outside the grid.
        if self.start.shape != (3,) or np.any(self.start < 0) or np.any(
            self.start >= np.array(passable.shape)
        ):
            raise ValueError(f"start {self.start.tolist()} is outside the grid {passable.shape}")
        if goals is not None and goals.shape != passable.shape:
            raise ValueError(f"goals shape {goals.shape} differs from the grid {passable.shape}")
        self.voxel_size = voxel_size
        goal_mask = goals if goals is not None else np.zeros(passable.shape, dtype=np.bool_)
        ws = _workspace(int(passable.size))
        s = int(np.ravel_multi_index(tuple(self.start), self.shape))
        ws.dist[s] = 0.0
        ws.touched[0] = s
        heap = _new_heap(1 << 12)
        _heap_push(heap, 0, 0.0, s)
        count, size = 1, 1
        max_cost = max_cost_m / voxel_size
        try:
            if isinstance(accept, CompiledAccept):
                goal, ws.touched, count, heap, size = accept.search_on(
                    passable, goal_mask, max_cost, ws.dist, ws.parent, ws.done, ws.touched,
                    count, heap, size)
            else:
                goal = -1
                while True:
                    goal, ws.touched, count, heap, size = resume_search(
                        passable, goal_mask, max_cost, ws.dist, ws.parent, ws.done,
                        ws.touched, count, heap, size, goal,
                    )
                    if goal < 0 or accept is None or accept(
                        np.array(np.unravel_index(goal, self.shape), dtype=np.int64)
                    ):
                        break
        except BaseException:
            # A test that raised left the buffers dirty, and which voxels it touched is lost
            # with the search's counts: the thread's next search starts from clean ones.
            _WORKSPACES.current = None
            raise
        visited = ws.touched[:count]
        # What every query but the nearest goal's needs, the visited voxels sorted for lookup,
        # is made on the first such query: a planner that asks only for the nearest goal's
        # path (Classic, at every plan) does not pay for a sort of the whole search.
        self._visited = visited.copy()
        self._visited_dist = ws.dist[visited]
        self._visited_parent = ws.parent[visited]
        self._goal_chain: list[int] = []
        self._goal_dist_m = float("inf")
        if goal >= 0:
            self._goal_chain.append(goal)
            while (up := int(ws.parent[self._goal_chain[-1]])) >= 0:
                self._goal_chain.append(up)
            self._goal_dist_m = float(ws.dist[goal] * voxel_size)
        ws.clean(visited)
        self.nearest_goal: IndexArray | None = (
            np.array(np.unravel_index(goal, self.shape), dtype=np.int64) if goal >= 0 else None
        )
        self._goal = goal

    @cached_property
    def _lookup(self) -> tuple[IndexArray, npt.NDArray[np.float64], IndexArray]:
        """The visited voxels' flat indices sorted, with their path lengths (m) and parents."""
        order = np.argsort(self._visited, kind="stable")
        lookup = (self._visited[order], self._visited_dist[order] * self.voxel_size,
                  self._visited_parent[order])
        # The unsorted arrays are not read again: only the sorted ones are kept.
        self._visited = self._visited_parent = np.zeros(0, dtype=np.int64)
        self._visited_dist = np.zeros(0, dtype=np.float64)
        return lookup

    @cached_property
    def dist_m(self) -> npt.NDArray[np.float64]:
        """(nx, ny, nz) path lengths in metres, inf where the search did not reach."""
        index, dist_m, _ = self._lookup
        flat = np.full(int(np.prod(self.shape)), np.inf, dtype=np.float64)
        flat[index] = dist_m
        grid: npt.NDArray[np.float64] = flat.reshape(self.shape)
        grid.setflags(write=False)
        return grid

    def _position(self, flat: int) -> int:
        """Where voxel `flat` is in the sorted visited arrays, -1 if it was not visited."""
        index = self._lookup[0]
        pos = int(np.searchsorted(index, flat))
        return pos if pos < len(index) and index[pos] == flat else -1

    def distance_to(self, voxel: npt.ArrayLike) -> float:
        """Path length (m) to `voxel` (3,), inf if the search did not reach it."""
        v = np.asarray(voxel, dtype=np.int64)
        flat = int(np.ravel_multi_index(tuple(v), self.shape))
        if flat == self._goal:
            return self._goal_dist_m
        pos = self._position(flat)
        return float(self._lookup[1][pos]) if pos >= 0 else float("inf")

    def path_to(self, goal: npt.ArrayLike) -> IndexArray:
        """(K, 3) voxel indices from the start to `goal`; empty if unreachable."""
        g = np.asarray(goal, dtype=np.int64)
        flat = int(np.ravel_multi_index(tuple(g), self.shape))
        if flat == self._goal:
            chain = self._goal_chain
        else:
            _, dist_m, parent = self._lookup
            pos = self._position(flat)
            if pos < 0 or not np.isfinite(dist_m[pos]):
                return np.zeros((0, 3), dtype=np.int64)
            chain = [flat]
            while (up := int(parent[pos])) >= 0:
                chain.append(up)
                pos = self._position(up)
        return np.stack(np.unravel_index(np.array(chain[::-1]), self.shape), axis=1)


@numba.njit(cache=True)
def segment_clear(mask: BoolGrid, a: npt.NDArray[np.float64], b: npt.NDArray[np.float64]) -> bool:
    """True if every voxel the segment a→b (in voxel units, continuous) passes is set in `mask`:
    the framework's own check (`sim.search_checks.segment_in_mask`), so that a path a planner
    finds clear is one the framework flies."""
    return segment_in_mask(mask, mask, a, b, False)


def shortcut(path: IndexArray, mask: BoolGrid) -> IndexArray:
    """Greedy line-of-sight simplification of a voxel path: (M, 3) with M <= K, same ends."""
    if len(path) <= 2:
        return path
    centres = path.astype(np.float64) + 0.5
    kept = [0]
    i = 0
    while i < len(path) - 1:
        j = len(path) - 1
        while j > i + 1 and not segment_clear(mask, centres[i], centres[j]):
            j -= 1
        kept.append(j)
        i = j
    return path[kept]
