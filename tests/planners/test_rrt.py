"""The random tree: every edge is collision-free, costs are path lengths, RRT* shortens them."""

from __future__ import annotations

import numpy as np
import pytest

from planners.rrt import Tree, extend, steer
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
