"""The random tree: every edge is collision-free, costs are path lengths, RRT* shortens them."""

from __future__ import annotations

import numpy as np
import pytest

from planners.rrt import Tree, _fails_surely, extend, next_sample, steer
from sim.occupancy import VoxelState
from sim.search_checks import plan_is_clear
from tests.planners.conftest import stack_from_state

VOXEL = 0.1
SHAPE = (50, 50, 20)


def _view():  # type: ignore[no-untyped-def]
    """Free box with two walls that leave a zig-zag passage."""
    state = np.full(SHAPE, VoxelState.FREE, dtype=np.uint8)
    state[0, :, :] = state[-1, :, :] = VoxelState.OCCUPIED
    state[:, 0, :] = state[:, -1, :] = VoxelState.OCCUPIED
    state[:, :, 0] = state[:, :, -1] = VoxelState.OCCUPIED
    state[16, :35, :] = VoxelState.OCCUPIED
    state[33, 15:, :] = VoxelState.OCCUPIED
    return stack_from_state(state, VOXEL, 0.3).view()


def _grow(rewire: float | None, seed: int, samples: int = 600) -> Tree:
    view = _view()
    rng = np.random.default_rng(seed)
    tree = Tree(np.array([0.8, 0.8, 1.0]))
    for _ in range(samples):
        extend(tree, view, rng.uniform([0, 0, 0], [5.0, 5.0, 2.0]), 0.8, rewire_radius_m=rewire)
    return tree


@pytest.mark.parametrize("rewire", [None, 1.2])
def test_every_edge_is_collision_free(rewire: float | None) -> None:
    view = _view()
    tree = _grow(rewire, 0)
    assert tree.size > 100
    for n in range(1, tree.size):
        a = tree.positions[tree.parents[n]]
        b = tree.positions[n]
        assert plan_is_clear(view.traversable, view.free, view.origin, VOXEL, a, b[None]) == 1
        idx = view.world_to_index(b[None])[0]
        assert view.traversable[tuple(idx)]
    # The tree got through the zig-zag into the far room.
    assert np.any(tree.positions[:, 0] > 3.4)


@pytest.mark.parametrize("rewire", [None, 1.2])
def test_costs_are_branch_lengths_and_there_are_no_cycles(rewire: float | None) -> None:
    tree = _grow(rewire, 1)
    for n in range(tree.size):
        branch = tree.branch(n)
        assert branch[0] == 0 and branch[-1] == n
        assert len(set(branch.tolist())) == len(branch)
        length = np.sum(np.linalg.norm(np.diff(tree.positions[branch], axis=0), axis=1))
        assert tree.costs[n] == pytest.approx(length, abs=1e-9)


def test_rrt_star_paths_are_shorter_on_average() -> None:
    plain = _grow(None, 2, 800)
    star = _grow(1.2, 2, 800)

    def detour(tree: Tree) -> float:
        straight = np.linalg.norm(tree.positions - tree.positions[0], axis=1)
        far = straight > 1.0
        return float(np.mean(tree.costs[far] / straight[far]))

    assert detour(star) < detour(plain)


def test_steer_caps_the_step() -> None:
    a = np.zeros(3)
    assert np.allclose(steer(a, np.array([3.0, 4.0, 0.0]), 1.0), [0.6, 0.8, 0.0])
    assert np.allclose(steer(a, np.array([0.3, 0.4, 0.0]), 1.0), [0.3, 0.4, 0.0])


def test_extend_refuses_unreachable_samples() -> None:
    view = _view()
    tree = Tree(np.array([0.8, 0.8, 1.0]))
    # Straight through the first wall.
    assert extend(tree, view, np.array([2.4, 0.8, 1.0]), 1.0) == -1
    assert tree.size == 1


def _grow_one_at_a_time(view, rng, tree, lo, hi, extension, limit):  # type: ignore[no-untyped-def]
    """The reference: draw, extend, count failures, stall past `limit` (as `grow_tree`)."""
    failures, events = 0, []
    while tree.size < 40:
        if failures > limit:
            events.append(("stalled", failures))
            break
        node = extend(tree, view, rng.uniform(lo, hi), extension)
        if node < 0:
            failures += 1
            continue
        events.append(("node", failures))
    return events


def _grow_screened(view, rng, tree, lo, hi, extension, limit):  # type: ignore[no-untyped-def]
    failures, events = 0, []
    while tree.size < 40:
        sample, skipped = next_sample(rng, lo, hi, tree, view, extension, limit - failures)
        failures += skipped
        if sample is None:
            events.append(("stalled", failures))
            break
        node = extend(tree, view, sample, extension)
        if node < 0:
            failures += 1
            continue
        events.append(("node", failures))
    return events


@pytest.mark.parametrize(("seed", "limit"), [(0, 10_000), (1, 10_000), (2, 40), (3, 3)])
def test_screened_samples_grow_the_tree_drawn_one_at_a_time(seed: int, limit: int) -> None:
    """Skipping the samples `extend` surely fails on, in compiled code, grows the same tree
    with the same failures, stalls at the same point, and leaves the generator where drawing
    one sample at a time leaves it."""
    view = _view()
    lo, hi = np.array([-1.0, -1.0, -0.5]), np.array([6.0, 6.0, 2.5])  # beyond the grid too
    ref_rng, rng = np.random.default_rng(seed), np.random.default_rng(seed)
    ref_tree, tree = Tree(np.array([0.8, 0.8, 1.0])), Tree(np.array([0.8, 0.8, 1.0]))
    expected = _grow_one_at_a_time(view, ref_rng, ref_tree, lo, hi, 0.8, limit)
    assert _grow_screened(view, rng, tree, lo, hi, 0.8, limit) == expected
    assert max(f for _, f in expected) > 0, "no sample failed"
    np.testing.assert_array_equal(tree.positions, ref_tree.positions)
    np.testing.assert_array_equal(tree.parents, ref_tree.parents)
    assert rng.bit_generator.state == ref_rng.bit_generator.state
    if limit == 3:
        assert expected[-1][0] == "stalled"


def test_the_screen_never_skips_a_sample_extend_takes() -> None:
    """Samples on voxel faces, at the extension's length and level with two nodes: where
    rounding could decide, the screen leaves the sample to `extend`."""
    view = _view()
    rng = np.random.default_rng(7)
    tree = _grow(None, 0, samples=200)
    grid = rng.integers(0, 50, size=(4000, 3)) * VOXEL * np.array([1.0, 1.0, 0.4])
    off_grid = rng.uniform([0, 0, 0], [5.0, 5.0, 2.0], size=(4000, 3))
    node = tree.positions[rng.integers(0, tree.size, 4000)]
    direction = rng.normal(size=(4000, 3))
    at_reach = node + 0.8 * direction / np.linalg.norm(direction, axis=1)[:, None]
    pairs = rng.integers(0, tree.size, size=(2000, 2))
    level = (tree.positions[pairs[:, 0]] + tree.positions[pairs[:, 1]]) / 2.0  # midway: a tie
    screened = 0
    for sample in np.concatenate([grid, off_grid, at_reach, level]):
        surely = _fails_surely(tree.positions, sample, 0.8, view.origin, view.voxel_size,
                               view.traversable)
        copy = Tree(tree.positions[0])
        copy._pos, copy._parent, copy._cost = (tree._pos.copy(), tree._parent.copy(),
                                               tree._cost.copy())
        copy.size = tree.size
        took = extend(copy, view, sample, 0.8) >= 0
        assert not (surely and took), f"the screen skipped {sample.tolist()}, which extends"
        screened += surely
    assert screened > 1000


@pytest.mark.parametrize("allowed", [-3, -1, 0, 1, 31, 32, 33, 63, 64])
def test_where_every_sample_fails_the_screen_stalls_after_the_allowed_failures(
        allowed: int) -> None:
    """A root walled in by occupied voxels fails every sample: the screen skips exactly the
    samples the one-at-a-time loop would have drawn before stalling (one more than the failures
    allowed, none below zero) and leaves the generator as those draws leave it, whatever their
    place in a batch."""
    view = _view()
    lo, hi = np.array([0.2, 0.2, 0.2]), np.array([4.8, 4.8, 1.8])
    # (16, y, z) is the occupied wall: a root there reaches no traversable voxel.
    tree = Tree(np.array([1.65, 0.55, 1.05]))  # a voxel centre: no sample near a face
    rng, ref_rng = np.random.default_rng(allowed + 10), np.random.default_rng(allowed + 10)
    sample, skipped = next_sample(rng, lo, hi, tree, view, 0.8, allowed)
    drawn = max(allowed + 1, 0)
    for _ in range(drawn):
        assert extend(tree, view, ref_rng.uniform(lo, hi), 0.8) < 0
    assert sample is None and skipped == drawn
    assert rng.bit_generator.state == ref_rng.bit_generator.state
