"""A rapidly-exploring random tree (RRT, optionally RRT*) in the vehicle's traversable space.

Nodes are world positions; an edge is a straight segment whose quarter-voxel samples all lie in
traversable voxels (`planners.lines`), the framework's own test, so any branch of the tree can be
flown as it is. Samples are drawn by the caller's seeded generator, uniformly in a box.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from planners.lines import segment_clear_world, segments_clear
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
