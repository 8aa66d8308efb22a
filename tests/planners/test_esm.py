"""ESM: the persistent segment tree (value rewiring, re-rooting, lazy gains) and the
reconstruction gain, on hand-made maps."""

from __future__ import annotations

import copy
import math
from typing import Any

import numpy as np
import numpy.typing as npt
import pytest

from planners.esm import Esm, EsmConfig
from planners.gain import GainEvaluator
from planners.recon_gain import ReconGainEvaluator, column_sector_bits
from planners.registry import make, spec
from planners.segment_tree import (
    FlightTime,
    SegmentTree,
    insert,
    prune_blocked,
    value_under,
)
from sim.camera import CameraConfig
from sim.geometry import Pose
from sim.interface import Observation, PlannerContext, PlanOutcome
from sim.occupancy import VoxelState
from sim.vehicle import VehicleLimits
from tests.planners.conftest import stack_from_state

FLIGHT = FlightTime(v_max=1.5, a_max=2.5, yaw_rate_max=1.0, yaw_acc_max=2.0)
FloatArray = npt.NDArray[np.float64]


def _wall_clear(a: FloatArray, b: FloatArray) -> npt.NDArray[np.bool_]:
    """A wall x = 5 for y < 5: a segment crossing it there is blocked."""
    a, b = np.atleast_2d(a), np.atleast_2d(b)
    out = np.ones(len(a), dtype=bool)
    for n in range(len(a)):
        dx = b[n, 0] - a[n, 0]
        if (a[n, 0] - 5.0) * (b[n, 0] - 5.0) < 0.0 and abs(dx) > 1e-12:
            t = (5.0 - a[n, 0]) / dx
            out[n] = a[n, 1] + t * (b[n, 1] - a[n, 1]) >= 5.0
    return out


class _RecordingTree(SegmentTree):
    """Records the value of each node re-hung by `set_parent`, before and after the move."""

    def __init__(self, root: FloatArray) -> None:
        super().__init__(root, 0.0)
        self.moves: list[tuple[float, float]] = []

    def set_parent(self, node: int, parent: int, cost: float) -> None:
        before = float(self.values()[node])
        super().set_parent(node, parent, cost)
        self.moves.append((before, float(self.values()[node])))


def _grown_tree(seed: int, nodes: int = 120) -> _RecordingTree:
    """A tree grown by `insert` from random points (at most 1.5 m from their nearest node),
    checking that the best value in the tree never drops."""
    rng = np.random.default_rng(seed)
    tree = _RecordingTree(np.array([1.0, 1.0, 1.0]))
    while tree.size < nodes:
        p = np.array([*rng.uniform(0.0, 10.0, 2), rng.uniform(0.5, 2.0)])
        near = tree.nearest(p)
        d = p - tree.positions[near]
        if np.linalg.norm(d) > 1.5:
            p = tree.positions[near] + d * (1.5 / np.linalg.norm(d))
        best_before = tree.values()[tree.root]
        node = insert(tree, p, float(rng.uniform(-math.pi, math.pi)),
                      float(rng.exponential(2.0)), 0.0, _wall_clear, FLIGHT, 1.6, 20)
        if node >= 0:
            assert tree.values()[tree.root] >= best_before - 1e-12
    return tree


def _assert_edges_clear_and_acyclic(tree: SegmentTree) -> None:
    nodes = np.flatnonzero(tree.parents >= 0)
    assert np.all(_wall_clear(tree.positions[tree.parents[nodes]], tree.positions[nodes]))
    for n in range(tree.size):
        assert tree.path(n)[0] == tree.root  # every node reaches the root: no cycle
        assert len(tree.path(n)) <= tree.size


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_rewiring_never_lowers_a_value_and_keeps_edges_clear(seed: int) -> None:
    tree = _grown_tree(seed)
    assert len(tree.moves) > 0, "no rewiring happened: the test tests nothing"
    for before, after in tree.moves:
        assert after > before
    _assert_edges_clear_and_acyclic(tree)


def test_value_is_best_gain_per_second_of_any_branch_below() -> None:
    tree = SegmentTree(np.zeros(3), 0.0)
    a = tree.add([1.0, 0.0, 0.0], tree.root, 0.0, 2.0, gain=2.0)
    b = tree.add([2.0, 0.0, 0.0], a, 0.0, 2.0, gain=10.0)
    c = tree.add([1.0, 1.0, 0.0], a, 0.0, 1.0, gain=0.0)
    values = tree.values()
    assert values[b] == pytest.approx(12.0 / 4.0)
    assert values[c] == pytest.approx(2.0 / 3.0)
    assert values[a] == pytest.approx(3.0)
    sums = tree.accumulate()
    # Hung straight from the root by a 1 s segment, b alone would be worth 10 per second.
    assert value_under(tree, b, tree.root, 1.0, sums) == pytest.approx(10.0)


def test_rerooting_keeps_the_chosen_subtree_and_the_rest() -> None:
    tree = _grown_tree(3, nodes=80)
    child = int(tree.children(tree.root)[0])
    below = np.flatnonzero(tree.descendants([child]))
    kept = {tuple(tree.positions[n]): tuple(tree.positions[tree.parents[n]])
            for n in below if n != child}
    old_root = tree.root
    size = tree.size
    tree.reroot(child, FLIGHT)
    assert tree.root == child
    assert tree.size == size
    assert tree.parents[old_root] == child
    # The chosen subtree is untouched; every node still reaches the new root.
    for n in range(tree.size):
        key = tuple(tree.positions[n])
        if key in kept:
            assert tuple(tree.positions[tree.parents[n]]) == kept[key]
    _assert_edges_clear_and_acyclic(tree)


def test_blocked_segments_are_reconnected_or_dropped() -> None:
    tree = SegmentTree(np.array([4.0, 6.0, 1.0]), 0.0)
    a = tree.add([4.5, 4.0, 1.0], tree.root, 0.0, 1.0)
    b = tree.add([5.5, 4.0, 1.0], a, 0.0, 1.0)  # crosses the wall: blocked
    tree.add([5.5, 3.0, 1.0], b, 0.0, 1.0)
    # b can be reached from the root's side above the wall's end? Only via a node there.
    dropped, reconnected = prune_blocked(tree, _wall_clear, FLIGHT, 1.6, 20)
    assert (dropped, reconnected) == (2, 0)
    assert tree.size == 2
    tree = SegmentTree(np.array([4.0, 6.0, 1.0]), 0.0)
    a = tree.add([4.5, 4.0, 1.0], tree.root, 0.0, 1.0)
    tree.add([5.5, 5.5, 1.0], tree.root, 0.0, 1.0)
    b = tree.add([5.5, 4.5, 1.0], a, 0.0, 1.0)  # blocked, but clear from the node above it
    dropped, reconnected = prune_blocked(tree, _wall_clear, FLIGHT, 1.6, 20)
    assert (dropped, reconnected) == (0, 1)
    _assert_edges_clear_and_acyclic(tree)


class _CountingEsm(Esm):
    """An ESM whose gains come from a given function, counting recomputations."""

    def __init__(self, truth: dict[int, float]) -> None:
        super().__init__(EsmConfig())
        self.truth = truth
        self.evaluated: list[int] = []

    def refresh(self, tree: SegmentTree, view: object, node: int, now: float) -> None:
        self.evaluated.append(node)
        tree.gains[node] = self.truth[node]
        tree.stamps[node] = now


def test_lazy_reevaluation_recomputes_only_what_it_must() -> None:
    rng = np.random.default_rng(5)
    tree = _grown_tree(5, nodes=100)
    # Stale gains (computed at t=0) are upper bounds of the true ones.
    truth = {n: float(tree.gains[n] * rng.uniform(0.0, 1.0)) for n in range(tree.size)}
    truth[tree.root] = 0.0
    planner = _CountingEsm(truth)
    child, value = planner.select(tree, None, now=1.0)  # type: ignore[arg-type]
    # Brute force: every gain recomputed.
    full = copy.deepcopy(tree)
    full.gains[:] = [truth[n] for n in range(tree.size)]
    g, c, _ = full.accumulate()
    ratio = np.where(c > 0, g / np.maximum(c, 1e-12), 0.0)
    ratio[full.root] = -np.inf
    best = int(np.argmax(ratio))
    assert value == pytest.approx(ratio[best])
    assert child == full.root_child_of(best)
    assert 0 < len(planner.evaluated) < tree.size - 1
    assert len(set(planner.evaluated)) == len(planner.evaluated)  # none twice
    # A second call at the same time recomputes nothing.
    planner.evaluated.clear()
    assert planner.select(tree, None, now=1.0) == (child, pytest.approx(value))  # type: ignore[arg-type]
    assert planner.evaluated == []


# -- reconstruction gain -------------------------------------------------------------------

VOXEL = 0.1
SHAPE = (60, 40, 25)
CAMERA = CameraConfig()
HERE = np.array([3.05, 2.05, 1.25])


def _two_walls() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Known free everywhere, a wall 2 m ahead (+x) and one 2 m behind (-x): the one ahead
    seen by one frame from one direction, the one behind by 200 frames from all eight."""
    state = np.full(SHAPE, VoxelState.FREE, dtype=np.uint8)
    weight = np.zeros(SHAPE, dtype=np.uint8)
    seen = np.zeros(SHAPE, dtype=np.uint8)
    ahead, behind = 50, 10  # x = 5.0-5.1 and 1.0-1.1: 1.95 m from HERE either way
    state[ahead] = VoxelState.OCCUPIED
    state[behind] = VoxelState.OCCUPIED
    weight[ahead] = 1
    seen[ahead] = 1 << 2  # seen from +y only
    weight[behind] = 200
    seen[behind] = 0xFF
    return state, weight, seen


def _recon(**kwargs: Any) -> ReconGainEvaluator:
    return ReconGainEvaluator(CAMERA, 5.0, VOXEL, **kwargs)


def test_sector_bits_are_those_of_the_direction_back_to_the_camera() -> None:
    # Looking along +x, the camera lies toward -x of the surface: sector 4 (180°-225°).
    bits = column_sector_bits(np.array([0.0, math.pi / 2, math.pi, 1.5 * math.pi]))
    assert bits.tolist() == [1 << 4, 1 << 6, 1 << 0, 1 << 2]


def test_reconstruction_gain_prefers_the_poorly_observed_wall() -> None:
    state, weight, seen = _two_walls()
    stack = stack_from_state(state, VOXEL, 0.45)
    stack.surface._weight[...] = weight
    stack.surface._directions[...] = seen
    view = stack.view()
    gains = _recon()
    columns = gains.columns(view, HERE)
    poor, good = gains.at_yaw(columns, 0.0), gains.at_yaw(columns, math.pi)
    assert poor > 0.0
    assert poor > 5.0 * good
    # Either part alone ranks them the same way.
    weights_only = _recon(direction_bonus=0.0).columns(view, HERE)
    assert gains.at_yaw(weights_only, 0.0) > gains.at_yaw(weights_only, math.pi)
    directions_only = _recon(surface_weight=0.0).columns(view, HERE)
    assert gains.at_yaw(directions_only, 0.0) > 0.0
    assert gains.at_yaw(directions_only, math.pi) == 0.0
    # Nothing unknown: the volumetric gain sees nothing either way.
    assert GainEvaluator(CAMERA, 5.0, VOXEL).gain(view, HERE, 0.0) == 0.0


def test_well_seen_surfaces_stop_counting() -> None:
    """Fused from 5 frames (impact 1/6 < 0.2) and seen from two sectors: worth nothing."""
    state, weight, seen = _two_walls()
    weight[50] = 5
    seen[50] = (1 << 2) | (1 << 3)
    stack = stack_from_state(state, VOXEL, 0.45)
    stack.surface._weight[...] = weight
    stack.surface._directions[...] = seen
    gains = _recon()
    assert gains.at_yaw(gains.columns(stack.view(), HERE), 0.0) == 0.0
    weight[50] = 4  # impact 1/5: still counts
    stack.surface._weight[...] = weight
    assert gains.at_yaw(gains.columns(stack.view(), HERE), 0.0) > 0.0


def test_reconstruction_gain_counts_unknown_volume_like_the_volumetric_gain() -> None:
    state = np.zeros(SHAPE, dtype=np.uint8)
    state[15:45, 5:35, 3:22] = VoxelState.FREE
    view = stack_from_state(state, VOXEL, 0.45).view()
    recon = _recon().columns(view, HERE)
    volumetric = GainEvaluator(CAMERA, 5.0, VOXEL).columns(view, HERE)
    assert volumetric.sum() > 1.0
    np.testing.assert_allclose(recon, volumetric, rtol=1e-12, atol=1e-12)
    half = _recon(unknown_weight=0.5).columns(view, HERE)
    np.testing.assert_allclose(half, 0.5 * volumetric, rtol=1e-12)


# -- the planner ---------------------------------------------------------------------------

def _open_room() -> tuple[np.ndarray, float]:
    """A free room (1-5 m by 1-3 m) in unknown space."""
    state = np.zeros(SHAPE, dtype=np.uint8)
    state[10:50, 10:30, 3:22] = VoxelState.FREE
    return state, 0.45


def _context(seed: int = 0) -> PlannerContext:
    return PlannerContext(area="handmade", bounds_min=np.zeros(3),
                          bounds_max=np.array(SHAPE) * VOXEL, start=Pose(HERE.copy(), 0.0),
                          limits=VehicleLimits(), safety_radius_m=0.45, camera=CAMERA,
                          rng=np.random.default_rng(seed))


@pytest.mark.parametrize("name", ["esm-ipp-v1", "esm-recon-v1", "esm-ipp-v2", "esm-recon-v2"])
def test_tree_persists_and_is_rerooted_at_the_flown_segment(name: str) -> None:
    state, safety = _open_room()
    view = stack_from_state(state, VOXEL, safety).view()
    planner = make(name)
    assert isinstance(planner, Esm)
    planner.reset(_context())
    plan = planner.plan(Observation(0.0, Pose(HERE.copy(), 0.0), np.zeros(3), view,
                                    PlanOutcome.NONE))
    assert not plan.done
    tree = planner.tree
    assert tree is not None
    target = plan.waypoints[-1, :3].copy()
    child = tree.nearest(target)
    below = {tuple(np.round(p, 9)) for p in tree.positions[tree.descendants([child])]}
    size = tree.size
    plan2 = planner.plan(Observation(1.0, Pose(target.copy(), float(plan.waypoints[-1, 3])),
                                     np.zeros(3), view, PlanOutcome.REACHED))
    assert planner.tree is tree  # one tree for the whole flight
    np.testing.assert_allclose(tree.positions[tree.root], target)
    after = {tuple(np.round(p, 9)) for p in tree.positions}
    assert below <= after  # the flown child's subtree is kept
    assert tree.size >= size - 1  # at most the old root dropped, if it had nothing left
    assert plan2.info["mode"] in ("tree", "back")
    assert spec(name).id == name


def _corridor() -> np.ndarray:
    """A known free corridor along x, 1.3 m wide and 2 m high, walls round it, unknown
    elsewhere: the traversable part (0.45 m safety radius) is 0.4 m wide, so a sphere of
    `local_radius_m` round a node in it holds only a few nodes `density_radius_m` apart."""
    state = np.zeros(SHAPE, dtype=np.uint8)
    state[:, 13:28, 2:23] = VoxelState.OCCUPIED
    state[:, 14:27, 3:22] = VoxelState.FREE
    return state


@pytest.mark.parametrize("planner_id", ["esm-ipp-v1", "esm-ipp-v2"])
@pytest.mark.parametrize("sampling", ["box", "traversable"])
def test_a_root_in_a_narrow_corridor_does_not_starve_the_global_samples(
        sampling: str, planner_id: str) -> None:
    """The corridor cannot hold `local_count` nodes near the root; semilocal samples are
    counted as drawn, not as kept, so the rest of the tries are global and the tree grows along
    the corridor (drawing semilocal samples until enough were kept, it stayed within 1.5 m)."""
    view = stack_from_state(_corridor(), VOXEL, 0.45).view()
    start = np.array([0.55, 2.05, 1.25])
    planner = make(planner_id, {"global_sampling": sampling})
    assert isinstance(planner, Esm)
    planner.reset(_context())
    planner.plan(Observation(0.0, Pose(start.copy(), 0.0), np.zeros(3), view, PlanOutcome.NONE))
    tree = planner.tree
    assert tree is not None
    reach = np.linalg.norm(tree.positions - start, axis=1)
    assert np.count_nonzero(reach <= EsmConfig().local_radius_m) < EsmConfig().local_count
    assert reach.max() > 3.0
    assert np.all(view.traversable[tuple(view.world_to_index(tree.positions).T)])


def test_a_sample_is_steered_from_the_next_nearest_node_when_the_nearest_is_walled_off() -> None:
    """Two nodes: the nearest to the sample behind a wall, the next one in the open."""
    state = np.full(SHAPE, VoxelState.FREE, dtype=np.uint8)
    state[:, 20, :] = VoxelState.OCCUPIED  # a wall at y = 2.0-2.1 m
    view = stack_from_state(state, VOXEL, 0.45).view()
    sample = np.array([4.0, 1.0, 1.25])
    for candidates, steered in ((1, False), (2, True)):
        planner = make("esm-ipp-v1", {"steer_candidates": candidates})
        assert isinstance(planner, Esm)
        planner.reset(_context())
        tree = SegmentTree(np.array([3.6, 2.9, 1.25]))  # nearest, across the wall
        tree.add(np.array([1.5, 1.0, 1.25]), tree.root, 0.0, 1.0)  # next nearest, in the open
        new = planner._steer(tree, view, sample)
        assert (new is not None) == steered
        if new is not None:
            np.testing.assert_allclose(new, [3.0, 1.0, 1.25], atol=1e-9)
