"""The receding-horizon next-best-view tree shared by NBVP and AEP.

A random tree grows from the vehicle in traversable space, from samples drawn uniformly in a box
of half-size `sampling_radius_m` around the vehicle (clipped to the area; the whole area when
None), each edge at most `extension_m` long; each new node gets the gain of its view
(`planners.gain`), at a random yaw (NBVP) or at its best yaw (AEP), and a branch value

    value(n) = value(parent(n)) + gain(n) * exp(-lambda * cost(n)),

cost being the path length from the root (Bircher et al., ICRA 2016, eq. 1). Growth goes on
until the tree has `min_nodes` nodes (N_init) and some branch is worth more than `zero_gain`
(NBVP: 0, any gain at all), or gives up at `max_nodes` nodes (N_tol). The previous
iteration's best branch, less its flown first edge, seeds the new tree so that a good plan is
not lost to sampling.

The gain may be cast through a copy of the map with narrow gaps in its occupied surfaces
closed (`planners.surface_gaps`, NBVP's `surface_gap_m`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numba
import numpy as np
import numpy.typing as npt

from planners.gain import GainEvaluator
from planners.lines import segment_clear_world
from planners.rrt import Tree, extend, next_sample
from sim.map_view import MapView

FloatArray = npt.NDArray[np.float64]
IdArray = npt.NDArray[np.int64]
StateGrid = npt.NDArray[np.uint8]


@dataclass(frozen=True)
class TreeSettings:
    """How the tree grows and what a branch is worth (see the planners' configs)."""

    extension_m: float
    sampling_radius_m: float | None  # half-size of the sampling box; None: the whole area
    min_nodes: int
    max_nodes: int
    max_failures_per_node: int
    degressive_coeff: float
    zero_gain: float
    rewire_radius_m: float | None  # None: plain RRT
    yaw: Literal["random", "best"]


@dataclass
class TreeOutcome:
    """A grown tree and its best node (-1 when the tree is only its root)."""

    tree: Tree
    best: int
    best_value: float
    gain_found: bool
    stalled: bool  # too many failed samples: the tree cannot grow from here


def _node_gain(gains: GainEvaluator, view: MapView, position: FloatArray, yaw_mode: str,
               rng: np.random.Generator, state: StateGrid | None) -> tuple[float, float]:
    columns = gains.columns(view, position, state)
    if yaw_mode == "best":
        best = gains.best(columns)
        return best.yaw, best.gain
    yaw = float(rng.uniform(-math.pi, math.pi))
    return yaw, gains.at_yaw(columns, yaw)


@numba.njit(cache=True)
def _branch_sums(own: FloatArray, parents: IdArray) -> FloatArray:
    """(N,) each node's `own` plus its ancestors', by pointer jumping: each round adds to every
    node the sum it does not hold yet of its nearest ancestor's chain, doubling the ancestors
    summed. The additions, and so the rounding, do not depend on the order of ids."""
    n = own.shape[0]
    acc = own.copy()
    up = parents.copy()
    new_acc = np.empty(n)
    new_up = np.empty(n, dtype=np.int64)
    while True:
        active = False
        for i in range(n):
            u = up[i]
            if u >= 0:
                active = True
                new_acc[i] = acc[i] + acc[u]
                new_up[i] = up[u]
            else:
                new_acc[i] = acc[i]
                new_up[i] = u
        if not active:
            return acc
        acc, new_acc = new_acc, acc
        up, new_up = new_up, up


def _values(tree: Tree, degressive: float) -> FloatArray:
    """(N,) branch values from the node gains, whatever the order of ids (RRT* re-hangs
    nodes under newer ones)."""
    # The discount stays NumPy's exp: a compiled exp may round differently.
    return _branch_sums(tree.gains * np.exp(-degressive * tree.costs), tree.parents)


def grow_tree(
    view: MapView,
    gains: GainEvaluator,
    settings: TreeSettings,
    rng: np.random.Generator,
    root: FloatArray,
    root_yaw: float,
    bounds_min: FloatArray,
    bounds_max: FloatArray,
    seed_branch: FloatArray | None = None,
    gain_state: StateGrid | None = None,
) -> TreeOutcome:
    """Grow a tree from `root` (world (3,)).

    Args:
        seed_branch: (M, 4) x, y, z, yaw of the previous best branch, re-inserted as a chain
            from the root as far as its edges are still clear.
        gain_state: (nx, ny, nz) voxel states the gains are cast through instead of the map's.
    """
    tree = Tree(root, root_yaw)
    if seed_branch is not None:
        parent = 0
        for row in seed_branch:
            p = row[:3]
            voxel = view.world_to_index(p[None])[0]
            if not (np.all(view.in_bounds(voxel[None]))
                    and view.traversable[voxel[0], voxel[1], voxel[2]]
                    and segment_clear_world(view, view.traversable, tree.positions[parent], p)):
                break
            parent = tree.add(p.copy(), parent, float(row[3]))
            yaw, gain = _node_gain(gains, view, p, settings.yaw, rng, gain_state)
            tree.gains[parent] = gain
            tree.yaws[parent] = yaw
    values = _values(tree, settings.degressive_coeff)
    lo, hi = bounds_min, bounds_max
    if settings.sampling_radius_m is not None:
        lo = np.maximum(lo, root - settings.sampling_radius_m)
        hi = np.minimum(hi, root + settings.sampling_radius_m)
    failures = 0
    stalled = False
    while True:
        nodes = tree.size - 1
        best_value = float(values[1:].max()) if nodes else 0.0
        if nodes >= settings.min_nodes and best_value > settings.zero_gain:
            break
        if nodes >= settings.max_nodes:
            break
        limit = settings.max_failures_per_node * (nodes + 1)
        # The samples `extend` surely fails on are skipped in compiled code, each counted as
        # a failure; the generator ends as if they had been drawn one at a time.
        sample, skipped = next_sample(rng, lo, hi, tree, view, settings.extension_m,
                                      limit - failures)
        failures += skipped
        if sample is None:
            stalled = True
            break
        before = tree.size
        node = extend(tree, view, sample, settings.extension_m,
                      rewire_radius_m=settings.rewire_radius_m)
        if node < 0:
            failures += 1
            continue
        yaw, gain = _node_gain(gains, view, tree.positions[node], settings.yaw, rng,
                               gain_state)
        tree.yaws[node] = yaw
        tree.gains[node] = gain
        if settings.rewire_radius_m is None and tree.size == before + 1:
            # Plain RRT never re-hangs nodes: the new value follows from its parent's.
            parent = int(tree.parents[node])
            values = np.append(values, values[parent] + gain * math.exp(
                -settings.degressive_coeff * tree.costs[node]))
        else:
            values = _values(tree, settings.degressive_coeff)
    if tree.size == 1:
        return TreeOutcome(tree, -1, 0.0, False, stalled)
    best = int(np.argmax(values[1:])) + 1
    tree.values[:] = values
    best_value = float(values[best])
    return TreeOutcome(tree, best, best_value, best_value > settings.zero_gain, stalled)
