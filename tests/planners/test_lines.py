"""Straight-line checks in world coordinates against a brute-force sampling of the segment."""

from __future__ import annotations

import numpy as np
import pytest

from planners.lines import farthest_clear_point, reachable_lengths, segments_clear
from sim.map_view import MappingStack
from sim.occupancy import VoxelState
from sim.search_checks import plan_is_clear
from tests.planners.conftest import stack_from_state

SHAPE = (30, 30, 12)
VOXEL = 0.1


def _stack() -> MappingStack:
    """Everything free except a wall across x = 1.5 m with a gap, so traversability varies."""
    state = np.full(SHAPE, VoxelState.FREE, dtype=np.uint8)
    state[15, :, :] = VoxelState.OCCUPIED
    state[15, 12:18, 3:9] = VoxelState.FREE
    return stack_from_state(state, VOXEL, 0.2)


def _brute_clear(mask: np.ndarray, a: np.ndarray, b: np.ndarray) -> bool:
    av, bv = a / VOXEL, b / VOXEL
    steps = max(1, int(np.ceil(np.linalg.norm(bv - av) * 4.0)))
    for s in range(steps + 1):
        p = np.floor(av + (bv - av) * s / steps).astype(int)
        if np.any(p < 0) or np.any(p >= np.array(mask.shape)) or not mask[tuple(p)]:
            return False
    return True


def test_segments_clear_matches_brute_force() -> None:
    view = _stack().view()
    rng = np.random.default_rng(3)
    a = rng.uniform(0.05, [2.95, 2.95, 1.15], size=(300, 3))
    b = rng.uniform(0.05, [2.95, 2.95, 1.15], size=(300, 3))
    got = segments_clear(view, view.traversable, a, b)
    expected = [_brute_clear(view.traversable, x, y) for x, y in zip(a, b, strict=True)]
    assert got.tolist() == expected
    assert 0 < np.count_nonzero(got) < len(got)


def test_farthest_clear_point_is_flyable_and_maximal() -> None:
    view = _stack().view()
    rng = np.random.default_rng(5)
    start = np.array([0.8, 1.5, 0.6])
    ends = rng.uniform(0.05, [2.95, 2.95, 1.15], size=(60, 3))
    lengths = reachable_lengths(view, start, ends)
    for end, length in zip(ends, lengths, strict=True):
        point = farthest_clear_point(view, start, end)
        assert point is not None
        # The framework accepts the leg to the point.
        assert plan_is_clear(view.traversable, view.free, view.origin, VOXEL, start,
                             point[None]) == 1
        reached = float(np.linalg.norm(point - start))
        assert reached <= length + 1e-9
        # Going a voxel further along the same line is refused (unless the end was reached).
        if reached < np.linalg.norm(end - start) - 0.2:
            further = start + (end - start) * (reached + 0.2) / np.linalg.norm(end - start)
            assert plan_is_clear(view.traversable, view.free, view.origin, VOXEL, start,
                                 further[None]) == 0


def test_farthest_clear_point_from_outside_traversable_space() -> None:
    view = _stack().view()
    # Inside the wall: not even the start is usable.
    assert farthest_clear_point(view, np.array([1.55, 0.5, 0.6]), np.array([0.5, 0.5, 0.6])) \
        is None
    assert reachable_lengths(view, np.array([1.55, 0.5, 0.6]), np.array([[0.5, 0.5, 0.6]]))[0] \
        == pytest.approx(-1.0)


def test_escaping_leaves_non_traversable_space_through_free_voxels() -> None:
    view = _stack().view()
    # Free but too close to the wall: not traversable.
    start = np.array([1.42, 0.5, 0.6])
    idx = view.world_to_index(start[None])[0]
    assert view.free[tuple(idx)] and not view.traversable[tuple(idx)]
    away = np.array([0.5, 0.5, 0.6])
    assert farthest_clear_point(view, start, away) is None
    point = farthest_clear_point(view, start, away, escaping=True)
    assert point is not None and np.linalg.norm(point - start) > 0.5
    assert plan_is_clear(view.traversable, view.free, view.origin, VOXEL, start,
                         point[None]) == 1
