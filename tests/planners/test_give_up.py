"""GiveUpTracker on maps made by hand: counts, the given-up cube, and what does not count."""

from __future__ import annotations

import numpy as np
import pytest

from planners.give_up import GiveUpTracker
from planners.search import IndexArray
from sim.geometry import Pose
from sim.interface import Observation, PlanOutcome
from sim.map_view import MapView
from sim.occupancy import VoxelState
from tests.planners.conftest import StackFactory

VOXEL = 0.1
SHAPE = (12, 12, 12)
# Single unknown voxels in free space: each makes its six face neighbours frontier voxels.
MIDDLE_UNKNOWN = (6, 6, 6)
CORNER_UNKNOWN = (0, 0, 0)
MIDDLE_TARGET = np.array([6, 6, 7], dtype=np.int64)
CORNER_TARGET = np.array([1, 0, 0], dtype=np.int64)


def _view(make_stack: StackFactory, *unknown: tuple[int, int, int]) -> MapView:
    state = np.full(SHAPE, VoxelState.FREE, dtype=np.uint8)
    for voxel in unknown:
        state[voxel] = VoxelState.UNKNOWN
    return make_stack(state, VOXEL, 0.2).view()


def _obs(view: MapView, outcome: PlanOutcome = PlanOutcome.REACHED) -> Observation:
    return Observation(time=0.0, pose=Pose(np.zeros(3), 0.0), velocity=np.zeros(3), map=view,
                       last_outcome=outcome)


def _idx(*v: int) -> IndexArray:
    return np.array(v, dtype=np.int64)


def test_the_hand_made_targets_are_frontier(make_stack: StackFactory) -> None:
    view = _view(make_stack, MIDDLE_UNKNOWN, CORNER_UNKNOWN)
    assert view.frontier[tuple(MIDDLE_TARGET)]
    assert view.frontier[tuple(CORNER_TARGET)]
    assert not view.frontier[3, 3, 3]


def test_first_update_makes_an_empty_mask_of_the_map_shape(make_stack: StackFactory) -> None:
    view = _view(make_stack, MIDDLE_UNKNOWN)
    tracker = GiveUpTracker(after=2, radius_voxels=2)
    assert tracker.mask is None
    mask = tracker.update(_idx(6, 6, 9), None, None, _obs(view))
    assert mask.shape == SHAPE
    assert mask.dtype == np.bool_
    assert not mask.any()
    assert tracker.mask is mask
    assert tracker.visits == {}


def test_gives_up_a_cube_at_the_nth_arrival(make_stack: StackFactory) -> None:
    view = _view(make_stack, MIDDLE_UNKNOWN)
    tracker = GiveUpTracker(after=3, radius_voxels=2)
    goal = _idx(6, 6, 9)
    for visits in (1, 2):
        mask = tracker.update(goal, goal, MIDDLE_TARGET, _obs(view))
        assert tracker.visits == {(6, 6, 7): visits}
        assert not mask.any()
    mask = tracker.update(goal, goal, MIDDLE_TARGET, _obs(view))
    assert tracker.visits == {(6, 6, 7): 3}
    expected = np.zeros(SHAPE, dtype=np.bool_)
    expected[4:9, 4:9, 5:10] = True  # the target +- 2 voxels on each axis
    np.testing.assert_array_equal(mask, expected)
    assert np.count_nonzero(mask) == 5**3
    # The mask is kept: further arrivals count on and mark the same cube again.
    again = tracker.update(goal, goal, MIDDLE_TARGET, _obs(view))
    assert again is mask
    assert tracker.visits == {(6, 6, 7): 4}
    np.testing.assert_array_equal(again, expected)


def test_radius_zero_gives_up_the_target_alone(make_stack: StackFactory) -> None:
    view = _view(make_stack, MIDDLE_UNKNOWN)
    tracker = GiveUpTracker(after=1, radius_voxels=0)
    mask = tracker.update(_idx(6, 6, 8), _idx(6, 6, 8), MIDDLE_TARGET, _obs(view))
    assert np.count_nonzero(mask) == 1
    assert mask[tuple(MIDDLE_TARGET)]


def test_cube_is_clipped_at_the_grid_low_edge(make_stack: StackFactory) -> None:
    view = _view(make_stack, CORNER_UNKNOWN)
    tracker = GiveUpTracker(after=1, radius_voxels=2)
    goal = _idx(3, 0, 0)
    mask = tracker.update(goal, goal, CORNER_TARGET, _obs(view))
    # Target (1, 0, 0): x from -1, y and z from -2, all clipped to 0 (not wrapped around).
    expected = np.zeros(SHAPE, dtype=np.bool_)
    expected[0:4, 0:3, 0:3] = True
    np.testing.assert_array_equal(mask, expected)
    assert np.count_nonzero(mask) == 4 * 3 * 3


def test_targets_are_counted_apart(make_stack: StackFactory) -> None:
    view = _view(make_stack, MIDDLE_UNKNOWN, CORNER_UNKNOWN)
    tracker = GiveUpTracker(after=2, radius_voxels=1)
    middle_goal, corner_goal = _idx(6, 6, 9), _idx(3, 0, 0)
    tracker.update(middle_goal, middle_goal, MIDDLE_TARGET, _obs(view))
    mask = tracker.update(corner_goal, corner_goal, CORNER_TARGET, _obs(view))
    assert tracker.visits == {(6, 6, 7): 1, (1, 0, 0): 1}
    assert not mask.any()
    mask = tracker.update(corner_goal, corner_goal, CORNER_TARGET, _obs(view))
    assert tracker.visits == {(6, 6, 7): 1, (1, 0, 0): 2}
    assert np.count_nonzero(mask) == 3 * 2 * 2
    assert not mask[tuple(MIDDLE_TARGET)]


def test_no_give_up_once_the_target_is_no_longer_frontier(make_stack: StackFactory) -> None:
    view = _view(make_stack)  # all free: the target was cleared
    assert not view.frontier[tuple(MIDDLE_TARGET)]
    tracker = GiveUpTracker(after=1, radius_voxels=2)
    goal = _idx(6, 6, 9)
    for _ in range(3):
        mask = tracker.update(goal, goal, MIDDLE_TARGET, _obs(view))
    assert tracker.visits == {}
    assert not mask.any()


@pytest.mark.parametrize("outcome", [PlanOutcome.NONE, PlanOutcome.BLOCKED,
                                     PlanOutcome.INVALID, PlanOutcome.FLYING])
def test_no_count_unless_the_plan_was_reached(make_stack: StackFactory,
                                              outcome: PlanOutcome) -> None:
    view = _view(make_stack, MIDDLE_UNKNOWN)
    tracker = GiveUpTracker(after=1, radius_voxels=2)
    goal = _idx(6, 6, 9)
    mask = tracker.update(goal, goal, MIDDLE_TARGET, _obs(view, outcome))
    assert tracker.visits == {}
    assert not mask.any()


def test_arrival_means_within_one_voxel_of_the_goal(make_stack: StackFactory) -> None:
    view = _view(make_stack, MIDDLE_UNKNOWN)
    tracker = GiveUpTracker(after=5, radius_voxels=2)
    goal = _idx(6, 6, 9)
    tracker.update(_idx(7, 5, 10), goal, MIDDLE_TARGET, _obs(view))  # one voxel on each axis
    assert tracker.visits == {(6, 6, 7): 1}
    tracker.update(_idx(6, 6, 11), goal, MIDDLE_TARGET, _obs(view))  # two voxels away
    assert tracker.visits == {(6, 6, 7): 1}
