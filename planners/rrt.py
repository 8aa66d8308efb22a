"""A rapidly-exploring random tree (RRT, optionally RRT*) in the vehicle's traversable space.

Nodes are world positions; an edge is a straight segment whose quarter-voxel samples all lie in
traversable voxels (`planners.lines`), the framework's own test, so any branch of the tree can be
flown as it is. Samples are drawn by the caller's seeded generator, uniformly in a box.
"""

from __future__ import annotations

import math

import numba
import numpy as np
import numpy.typing as npt

from planners.lines import segment_clear_world, segments_clear
from planners.screen_margin import near_integer, near_value
from planners.search import BoolGrid
from sim.map_view import MapView

FloatArray = npt.NDArray[np.float64]
IdArray = npt.NDArray[np.int64]


class Tree:
    """A tree rooted at node 0.

    Attributes (views of the first `size` rows):
        positions: (N, 3) world metres.  parents: (N,) parent id, -1 for the root.
        costs: (N,) path length from the root, metres.  yaws: (N,) rad.
        gains: (N,) a planner's own per-node gain.  values: (N,) a planner's branch value.
    """

    def __init__(self, root: npt.ArrayLike, yaw: float = 0.0, capacity: int = 256) -> None:
        self._pos = np.zeros((capacity, 3))
        self._parent = np.full(capacity, -1, dtype=np.int64)
        self._cost = np.zeros(capacity)
        self._yaw = np.zeros(capacity)
        self._gain = np.zeros(capacity)
        self._value = np.zeros(capacity)
        self.size = 0
        self.add(np.asarray(root, dtype=np.float64), -1, yaw)

    def _grow(self) -> None:
        n = len(self._pos) * 2
        self._pos = np.resize(self._pos, (n, 3))
        self._parent = np.resize(self._parent, n)
        self._cost = np.resize(self._cost, n)
        self._yaw = np.resize(self._yaw, n)
        self._gain = np.resize(self._gain, n)
        self._value = np.resize(self._value, n)

    def add(self, position: FloatArray, parent: int, yaw: float = 0.0) -> int:
        """Append a node under `parent` (-1 only for the root); returns its id."""
        if self.size == len(self._pos):
            self._grow()
        n = self.size
        self._pos[n] = position
        self._parent[n] = parent
        self._cost[n] = (self._cost[parent] + float(np.linalg.norm(position - self._pos[parent]))
                         if parent >= 0 else 0.0)
        self._yaw[n] = yaw
        self._gain[n] = 0.0
        self._value[n] = 0.0
        self.size += 1
        return n

    @property
    def positions(self) -> FloatArray:
        return self._pos[: self.size]

    @property
    def parents(self) -> IdArray:
        return self._parent[: self.size]

    @property
    def costs(self) -> FloatArray:
        return self._cost[: self.size]

    @property
    def yaws(self) -> FloatArray:
        return self._yaw[: self.size]

    @property
    def gains(self) -> FloatArray:
        return self._gain[: self.size]

    @property
    def values(self) -> FloatArray:
        return self._value[: self.size]

    def branch(self, node: int) -> IdArray:
        """Node ids from the root to `node`, both included."""
        chain = [node]
        while self._parent[chain[-1]] >= 0:
            chain.append(int(self._parent[chain[-1]]))
        return np.array(chain[::-1], dtype=np.int64)

    def nearest(self, point: FloatArray) -> int:
        return int(np.argmin(np.sum((self.positions - point) ** 2, axis=1)))

    def near(self, point: FloatArray, radius: float) -> IdArray:
        d2 = np.sum((self.positions - point) ** 2, axis=1)
        return np.flatnonzero(d2 <= radius * radius).astype(np.int64)

    def set_parent(self, node: int, parent: int) -> None:
        """Re-hang `node` (and its subtree) under `parent`, updating subtree costs."""
        self._parent[node] = parent
        delta = (self._cost[parent] + float(np.linalg.norm(self._pos[node] - self._pos[parent]))
                 - self._cost[node])
        stack = [node]
        while stack:
            n = stack.pop()
            self._cost[n] += delta
            stack.extend(int(c) for c in np.flatnonzero(self.parents == n))


def steer(nearest: FloatArray, sample: FloatArray, extension_m: float) -> FloatArray:
    """The point at most `extension_m` from `nearest` toward `sample`."""
    d = sample - nearest
    length = float(np.linalg.norm(d))
    if length <= extension_m:
        return sample.copy()
    result: FloatArray = nearest + d * (extension_m / length)
    return result


def extend(
    tree: Tree,
    view: MapView,
    sample: FloatArray,
    extension_m: float,
    *,
    rewire_radius_m: float | None = None,
    yaw: float = 0.0,
) -> int:
    """One RRT (or, with `rewire_radius_m`, RRT*) step toward `sample`.

    Returns:
        The new node's id, or -1 when the steered point or its edge is not traversable.
    """
    mask = view.traversable
    near_id = tree.nearest(sample)
    new = steer(tree.positions[near_id], sample, extension_m)
    if np.linalg.norm(new - tree.positions[near_id]) < 1e-6:
        return -1
    voxel = view.world_to_index(new[None])[0]
    if not (np.all(view.in_bounds(voxel[None])) and mask[voxel[0], voxel[1], voxel[2]]):
        return -1
    if not segment_clear_world(view, mask, tree.positions[near_id], new):
        return -1
    parent = near_id
    if rewire_radius_m is None:
        return tree.add(new, parent, yaw)
    # RRT*: the cheapest clear parent among the neighbours, then re-hang neighbours through the
    # new node when that shortens their path.
    neighbours = tree.near(new, rewire_radius_m)
    candidates = neighbours[neighbours != near_id]
    if len(candidates):
        via = tree.costs[candidates] + np.linalg.norm(tree.positions[candidates] - new, axis=1)
        better = candidates[via < tree.costs[near_id] + np.linalg.norm(
            tree.positions[near_id] - new) - 1e-9]
        if len(better):
            order = np.argsort(tree.costs[better] + np.linalg.norm(
                tree.positions[better] - new, axis=1), kind="stable")
            ok = segments_clear(view, mask, tree.positions[better[order]],
                                np.repeat(new[None], len(better), axis=0))
            if np.any(ok):
                parent = int(better[order][int(np.argmax(ok))])
    node = tree.add(new, parent, yaw)
    others = neighbours[(neighbours != parent) & (neighbours != 0)]
    if len(others):
        via = tree.costs[node] + np.linalg.norm(tree.positions[others] - new, axis=1)
        shorter = others[via < tree.costs[others] - 1e-9]
        if len(shorter):
            ok = segments_clear(view, mask, np.repeat(new[None], len(shorter), axis=0),
                                tree.positions[shorter])
            ancestors = set(tree.branch(node).tolist())
            for n in shorter[ok]:
                if int(n) not in ancestors:  # re-hanging an ancestor would close a cycle
                    tree.set_parent(int(n), node)
    return node


@numba.njit(cache=True)
def _fails_surely(positions: FloatArray, sample: FloatArray, extension_m: float,
                  origin: FloatArray, voxel_size: float, mask: BoolGrid) -> bool:
    """Whether `extend` toward `sample` returns -1, decided only where no rounding can change
    the answer (False: it may succeed, or the screen cannot tell)."""
    # The nearest node, as `Tree.nearest` finds it; a near tie could go either way.
    best, second, near = math.inf, math.inf, 0
    for r in range(positions.shape[0]):
        d0 = positions[r, 0] - sample[0]
        d1 = positions[r, 1] - sample[1]
        d2 = positions[r, 2] - sample[2]
        q = (d0 * d0 + d1 * d1) + d2 * d2
        if q < best:
            best, second, near = q, best, r
        elif q < second:
            second = q
    if near_value(second, best):
        return False
    # `steer`'s new point.
    d = sample - positions[near]
    length = math.sqrt((d[0] * d[0] + d[1] * d[1]) + d[2] * d[2])
    if near_value(length, extension_m) or length < 1e-3:
        return False
    new = sample.copy() if length <= extension_m else positions[near] + d * (extension_m / length)
    nx, ny, nz = mask.shape
    b = (new - origin) / voxel_size
    if not (near_integer(b[0]) or near_integer(b[1]) or near_integer(b[2])):
        i, j, k = math.floor(b[0]), math.floor(b[1]), math.floor(b[2])
        if not (0 <= i < nx and 0 <= j < ny and 0 <= k < nz) or not mask[i, j, k]:
            return True
    # The edge, sampled as `sim.search_checks.segment_in_mask` samples it: any sample surely
    # outside the mask fails it. An edge of the full extension is a whole number of quarter
    # voxels long, where rounding decides between two sample counts: it fails surely when it
    # does with either.
    a = (positions[near] - origin) / voxel_size
    span = math.sqrt(np.sum((b - a) ** 2)) * 4.0
    if not near_integer(span):
        return _edge_fails_surely(a, b, max(1, math.ceil(span)), mask)
    n = math.floor(span + 0.5)
    return (_edge_fails_surely(a, b, max(1, n), mask)
            and _edge_fails_surely(a, b, max(1, n + 1), mask))


@numba.njit(cache=True)
def _edge_fails_surely(a: FloatArray, b: FloatArray, steps: int, mask: BoolGrid) -> bool:
    """Whether one of the `steps + 1` samples of a→b (voxel units) lies surely outside `mask`:
    out of the grid or in a voxel not set, and not within the margin of a voxel face."""
    nx, ny, nz = mask.shape
    for s in range(steps + 1):
        t = s / steps
        x = a[0] + (b[0] - a[0]) * t
        y = a[1] + (b[1] - a[1]) * t
        z = a[2] + (b[2] - a[2]) * t
        if near_integer(x) or near_integer(y) or near_integer(z):
            continue
        i, j, k = math.floor(x), math.floor(y), math.floor(z)
        if not (0 <= i < nx and 0 <= j < ny and 0 <= k < nz) or not mask[i, j, k]:
            return True
    return False


@numba.njit(cache=True)
def _first_maybe(positions: FloatArray, samples: FloatArray, extension_m: float,
                 origin: FloatArray, voxel_size: float, mask: BoolGrid, count: int) -> int:
    """The first of `samples[:count]` toward which `extend` may succeed; `count` if none."""
    for n in range(count):
        if not _fails_surely(positions, samples[n], extension_m, origin, voxel_size, mask):
            return n
    return count


# Samples drawn ahead per screening call: most samples of a tree fail (about 11 in 12 on
# OFFICES C), so a batch usually holds the next one worth a real `extend`.
_SCREEN_BATCH = 32


def next_sample(rng: np.random.Generator, lo: FloatArray, hi: FloatArray, tree: Tree,
                view: MapView, extension_m: float, allowed_failures: int,
                ) -> tuple[FloatArray | None, int]:
    """The next of the samples `rng.uniform(lo, hi)` would draw one at a time toward which
    `extend` may succeed, skipping those it surely fails on, and how many it skipped; None
    once more than `allowed_failures` would have failed (the sample after them not drawn).

    Leaves `rng` exactly as drawing the samples one at a time up to the returned one would:
    a batch is drawn ahead, screened in compiled code, and the generator rewound to just past
    the sample returned. `extend` must still be asked about that sample."""
    if allowed_failures < 0:
        return None, 0
    mask = view.traversable
    skipped = 0
    while True:
        state = rng.bit_generator.state
        batch = rng.uniform(lo, hi, size=(_SCREEN_BATCH, 3))
        count = max(0, min(_SCREEN_BATCH, allowed_failures - skipped + 1))
        first = _first_maybe(tree.positions, batch, extension_m, view.origin, view.voxel_size,
                             mask, count)
        if first < count or count < _SCREEN_BATCH:
            used = first + 1 if first < count else count
            if used < _SCREEN_BATCH:
                rng.bit_generator.state = state
                rng.uniform(lo, hi, size=(used, 3))
            skipped += first
            return (batch[first].copy() if first < count else None), skipped
        skipped += _SCREEN_BATCH
