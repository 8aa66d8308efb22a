"""The persistent tree of trajectory segments of ESM (Schmid et al., RA-L 2020).

One tree, rooted at the vehicle, lives for the whole exploration: every planning call adds
segments to it, the vehicle flies the root's most valuable child, and that child becomes the new
root with the rest of the tree hanging from it. Each node is the end of one straight segment from
its parent, with the yaw the camera takes there, the gain of that view and the time the gain was
computed (gains go stale as the map fills in and are recomputed only when needed, by the caller).

Value of a node (the paper's normalized gain, propagated to the root's children):

    ratio(d) = sum of gains from the root (excluded) to d / sum of segment costs along that branch
    value(n) = max over d in the subtree of n of ratio(d)

so a segment is worth the best gain per unit cost of any branch continuing through it. Segment
cost is the flight time (see `FlightTime`).

RRT*-style growth (`insert`): a new node takes, among its nearby nodes with a clear edge, the
parent that maximises its value, and each such neighbour is re-hung under the new node when that
raises the neighbour's value.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from planners.segment_tree_kernels import branch_sums, nodes_below

FloatArray = npt.NDArray[np.float64]
IdArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

# clear(a, b): (N,) whether each straight segment a[n] -> b[n] ((N, 3) world) may be flown.
ClearFn = Callable[[FloatArray, FloatArray], BoolArray]

_EPS = 1e-12


@dataclass(frozen=True)
class FlightTime:
    """Time to fly a straight segment from rest to rest, turning the yaw on the way.

    The framework stops the vehicle at every waypoint, so each segment is flown from rest to
    rest: a trapezoidal speed profile (triangular when short) for the distance and one for the
    yaw change; the longer of the two (they run at the same time). Jerk limits are left out.
    """

    v_max: float
    a_max: float
    yaw_rate_max: float
    yaw_acc_max: float

    @staticmethod
    def _profile(distance: FloatArray, v: float, a: float) -> FloatArray:
        short = distance < v * v / a
        t: FloatArray = np.where(short, 2.0 * np.sqrt(distance / a), distance / v + v / a)
        return t

    def __call__(self, p0: FloatArray, yaw0: FloatArray | float, p1: FloatArray,
                 yaw1: FloatArray | float) -> FloatArray:
        """(N,) seconds from p0[n] (yaw0[n]) to p1[n] (yaw1[n]); positions (N, 3) or (3,)."""
        dist = np.linalg.norm(np.atleast_2d(p1) - np.atleast_2d(p0), axis=1)
        dyaw = np.abs((np.asarray(yaw1) - np.asarray(yaw0) + math.pi) % (2.0 * math.pi)
                      - math.pi)
        t: FloatArray = np.maximum(self._profile(dist, self.v_max, self.a_max),
                                   self._profile(np.broadcast_to(dyaw, dist.shape),
                                                 self.yaw_rate_max, self.yaw_acc_max))
        return t


class SegmentTree:
    """Nodes (segment ends) with a parent each; the root has parent -1.

    Attributes (views of the first `size` rows):
        positions: (N, 3) world metres.  yaws: (N,) rad.  parents: (N,) ids.
        gains: (N,) the view gain of each node.  stamps: (N,) simulated time its gain was
        computed (-inf: never).  costs: (N,) cost (s) of the segment from the parent.
    """

    def __init__(self, root: npt.ArrayLike, yaw: float = 0.0, capacity: int = 256) -> None:
        self._pos = np.zeros((capacity, 3))
        self._yaw = np.zeros(capacity)
        self._parent = np.full(capacity, -1, dtype=np.int64)
        self._gain = np.zeros(capacity)
        self._stamp = np.full(capacity, -np.inf)
        self._cost = np.zeros(capacity)
        self.size = 0
        self.root = self.add(np.asarray(root, dtype=np.float64), -1, yaw, 0.0)

    # -- storage ---------------------------------------------------------------------------
    def add(self, position: npt.ArrayLike, parent: int, yaw: float, cost: float,
            gain: float = 0.0, stamp: float = -np.inf) -> int:
        if self.size == len(self._pos):
            n = 2 * len(self._pos)
            self._pos = np.resize(self._pos, (n, 3))
            self._yaw = np.resize(self._yaw, n)
            self._parent = np.resize(self._parent, n)
            self._gain = np.resize(self._gain, n)
            self._stamp = np.resize(self._stamp, n)
            self._cost = np.resize(self._cost, n)
        k = self.size
        self._pos[k] = position
        self._yaw[k] = yaw
        self._parent[k] = parent
        self._gain[k] = gain
        self._stamp[k] = stamp
        self._cost[k] = cost
        self.size += 1
        return k

    @property
    def positions(self) -> FloatArray:
        return self._pos[: self.size]

    @property
    def yaws(self) -> FloatArray:
        return self._yaw[: self.size]

    @property
    def parents(self) -> IdArray:
        return self._parent[: self.size]

    @property
    def gains(self) -> FloatArray:
        return self._gain[: self.size]

    @property
    def stamps(self) -> FloatArray:
        return self._stamp[: self.size]

    @property
    def costs(self) -> FloatArray:
        return self._cost[: self.size]

    # -- structure -------------------------------------------------------------------------
    def children(self, node: int) -> IdArray:
        return np.flatnonzero(self.parents == node).astype(np.int64)

    def path(self, node: int) -> IdArray:
        """Ids from the root to `node`, both included."""
        chain = [node]
        while self._parent[chain[-1]] >= 0:
            chain.append(int(self._parent[chain[-1]]))
        return np.array(chain[::-1], dtype=np.int64)

    def descendants(self, nodes: npt.ArrayLike) -> BoolArray:
        """(N,) True on `nodes` and every node below them."""
        tops = np.zeros(self.size, dtype=bool)
        tops[np.asarray(nodes, dtype=np.int64)] = True
        return nodes_below(np.ascontiguousarray(self.parents), tops)

    def root_child_of(self, node: int) -> int:
        """The child of the root on the way to `node` (-1 for the root itself)."""
        chain = self.path(node)
        return int(chain[1]) if len(chain) > 1 else -1

    def accumulate(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(N,) gain sums, cost sums from the root, and node values (see the module)."""
        return branch_sums(np.ascontiguousarray(self.parents), np.ascontiguousarray(self.gains),
                           np.ascontiguousarray(self.costs))

    def values(self) -> FloatArray:
        return self.accumulate()[2]

    def nearest(self, point: FloatArray) -> int:
        return int(np.argmin(np.sum((self.positions - point) ** 2, axis=1)))

    def near(self, point: FloatArray, radius: float, count: int) -> IdArray:
        """At most `count` nearest node ids within `radius` of `point`, nearest first."""
        d2 = np.sum((self.positions - point) ** 2, axis=1)
        inside = np.flatnonzero(d2 <= radius * radius)
        order = inside[np.argsort(d2[inside], kind="stable")]
        result: IdArray = order[:count].astype(np.int64)
        return result

    # -- changes ---------------------------------------------------------------------------
    def set_parent(self, node: int, parent: int, cost: float) -> None:
        self._parent[node] = parent
        self._cost[node] = cost

    def reverse_to(self, node: int, flight: FlightTime) -> None:
        """Make `node` the top of its tree (the root's, or a detached subtree's), reversing the
        segments between it and the old top so that every node is kept."""
        chain = self.path(node)
        for a, b in zip(chain[:-1][::-1], chain[1:][::-1], strict=True):
            # b was a's child: a becomes b's child.
            self._parent[a] = b
            self._cost[a] = float(flight(self._pos[b], self._yaw[b], self._pos[a],
                                         self._yaw[a])[0])
        self._parent[node] = -1
        self._cost[node] = 0.0

    def reroot(self, node: int, flight: FlightTime) -> None:
        """Make `node` the root; the old root becomes a descendant of it (`reverse_to`)."""
        self.reverse_to(node, flight)
        self.root = int(node)

    def keep(self, mask: BoolArray) -> IdArray:
        """Drop the nodes where `mask` is False (never the root; a dropped node's descendants
        must be dropped too). Returns (old N,) new ids, -1 for dropped nodes."""
        mask = mask.copy()
        mask[self.root] = True
        new_id = np.full(self.size, -1, dtype=np.int64)
        kept = np.flatnonzero(mask)
        new_id[kept] = np.arange(len(kept))
        parents = self.parents[kept]
        remapped = np.where(parents >= 0, new_id[np.maximum(parents, 0)], -1)
        if np.any((parents >= 0) & (remapped < 0)):
            raise ValueError("a kept node's parent is dropped")
        n = len(kept)
        self._pos[:n] = self._pos[kept]
        self._yaw[:n] = self._yaw[kept]
        self._gain[:n] = self._gain[kept]
        self._stamp[:n] = self._stamp[kept]
        self._cost[:n] = self._cost[kept]
        self._parent[:n] = remapped
        self.size = n
        self.root = int(new_id[self.root])
        return new_id


def value_under(tree: SegmentTree, node: int, parent: int, cost: float,
                sums: tuple[FloatArray, FloatArray, FloatArray]) -> float:
    """Value `node` would have hung under `parent` by a segment of `cost` seconds, its
    subtree kept (sums: `tree.accumulate()` of the current tree)."""
    g, c, _ = sums
    below = np.flatnonzero(tree.descendants([node]))
    old_parent = int(tree.parents[node])
    g_base = g[old_parent] if old_parent >= 0 else 0.0
    gains = g[parent] + (g[below] - g_base)
    costs = c[parent] + cost + (c[below] - c[node])
    ratio = np.where(costs > _EPS, gains / np.maximum(costs, _EPS), 0.0)
    return float(ratio.max())


def insert(tree: SegmentTree, position: FloatArray, yaw: float, gain: float, stamp: float,
           clear: ClearFn, flight: FlightTime, rewire_radius_m: float,
           neighbours: int) -> int:
    """Add a node at `position` under the nearby parent that maximises its value, then re-hang
    each nearby node under it where that raises the node's value (RRT* rewiring by value).

    Returns:
        The new node's id, or -1 when no node within `rewire_radius_m` has a clear segment.
    """
    near = tree.near(position, rewire_radius_m, neighbours)
    if len(near) == 0:
        return -1
    ok = clear(tree.positions[near], np.repeat(position[None], len(near), axis=0))
    near = near[ok]
    if len(near) == 0:
        return -1
    sums = tree.accumulate()
    g, c, _ = sums
    costs = flight(tree.positions[near], tree.yaws[near], position, yaw)
    ratio = (g[near] + gain) / np.maximum(c[near] + costs, _EPS)
    # Highest value; the cheaper branch on ties (no gain anywhere yet: the shortest path).
    best = int(np.lexsort((c[near] + costs, -ratio))[0])
    node = tree.add(position, int(near[best]), yaw, float(costs[best]), gain, stamp)
    ancestors = set(tree.path(node).tolist())
    for other in near:
        n = int(other)
        if n in ancestors or n == tree.root:
            continue
        sums = tree.accumulate()
        cost = float(flight(tree.positions[node], tree.yaws[node], tree.positions[n],
                            tree.yaws[n])[0])
        if value_under(tree, n, node, cost, sums) > sums[2][n] + 1e-12:
            tree.set_parent(n, node, cost)
    return node


def rewire(tree: SegmentTree, node: int, clear: ClearFn, flight: FlightTime,
           rewire_radius_m: float, neighbours: int) -> bool:
    """Re-hang `node` under the nearby node (not below it, clear segment) that raises its
    value the most; returns whether it moved."""
    near = tree.near(tree.positions[node], rewire_radius_m, neighbours)
    below = tree.descendants([node])
    near = near[~below[near] & (near != tree.parents[node])]
    if len(near) == 0:
        return False
    ok = clear(tree.positions[near], np.repeat(tree.positions[node][None], len(near), axis=0))
    near = near[ok]
    if len(near) == 0:
        return False
    sums = tree.accumulate()
    costs = flight(tree.positions[near], tree.yaws[near], tree.positions[node],
                   tree.yaws[node])
    values = [value_under(tree, node, int(p), float(k), sums)
              for p, k in zip(near, costs, strict=True)]
    best = int(np.argmax(values))
    if values[best] <= sums[2][node] + 1e-12:
        return False
    tree.set_parent(node, int(near[best]), float(costs[best]))
    return True


def prune_blocked(tree: SegmentTree, clear: ClearFn, flight: FlightTime,
                  rewire_radius_m: float, neighbours: int) -> tuple[int, int]:
    """Re-check every segment. The subtree below a blocked one is reconnected where any of its
    nodes has a clear segment from a nearby node still connected to the root: the subtree is
    turned to hang from that node (`reverse_to`), which takes the quickest such parent
    (RRT*'s cheapest parent). What cannot be reconnected is dropped.

    Returns:
        (nodes dropped, subtrees reconnected).
    """
    nodes = np.flatnonzero(tree.parents >= 0)
    if len(nodes) == 0:
        return 0, 0
    ok = clear(tree.positions[tree.parents[nodes]], tree.positions[nodes])
    tops = [int(n) for n in nodes[~ok]]
    if not tops:
        return 0, 0
    for b in tops:
        tree.set_parent(b, -1, 0.0)
    reconnected = 0
    while tops:
        orphan = tree.descendants(tops)
        _, c, _ = tree.accumulate()
        link: tuple[int, int, float] | None = None
        for o in np.flatnonzero(orphan):
            near = tree.near(tree.positions[o], rewire_radius_m, neighbours)
            near = near[~orphan[near]]
            if len(near) == 0:
                continue
            near = near[clear(tree.positions[near],
                              np.repeat(tree.positions[o][None], len(near), axis=0))]
            if len(near) == 0:
                continue
            costs = flight(tree.positions[near], tree.yaws[near], tree.positions[o],
                           tree.yaws[o])
            best = int(np.argmin(c[near] + costs))
            link = (int(o), int(near[best]), float(costs[best]))
            break
        if link is None:
            break
        node, parent, cost = link
        top = int(tree.path(node)[0])
        tree.reverse_to(node, flight)
        tree.set_parent(node, parent, cost)
        tops.remove(top)
        reconnected += 1
    if not tops:
        return 0, reconnected
    dropped = tree.descendants(tops)
    tree.keep(~dropped)
    return int(np.count_nonzero(dropped)), reconnected
