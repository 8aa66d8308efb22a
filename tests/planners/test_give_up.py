"""GiveUpTracker on maps made by hand: counts, the given-up cube, and what does not count."""

from __future__ import annotations

import numpy as np
import pytest

from planners.give_up import GiveUpTracker
from planners.search import IndexArray
from sim.camera import CameraConfig
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


# -- visited frontiers: every frontier voxel looked at from a reached viewpoint ------------------

LONG = (60, 20, 20)  # 6 x 2 x 2 m, free; the vehicle at x = 0.55 m looks along +x
EYE = np.array([0.55, 1.05, 1.05])
EYE_VOXEL = _idx(5, 10, 10)


def _long_view(make_stack: StackFactory, unknown: list[tuple[int, int, int]],
               occupied: list[tuple[int, int, int]] = ()) -> MapView:  # type: ignore[assignment]
    state = np.full(LONG, VoxelState.FREE, dtype=np.uint8)
    for voxel in unknown:
        state[voxel] = VoxelState.UNKNOWN
    for voxel in occupied:
        state[voxel] = VoxelState.OCCUPIED
    return make_stack(state, VOXEL, 0.2).view()


def _looking(view: MapView, yaw: float = 0.0) -> Observation:
    return Observation(time=0.0, pose=Pose(EYE.copy(), yaw), velocity=np.zeros(3), map=view,
                       last_outcome=PlanOutcome.REACHED)


def _in_view_tracker(after: int = 2) -> GiveUpTracker:
    return GiveUpTracker(after=after, radius_voxels=2, camera=CameraConfig(), view_reach_m=3.5)


def test_frontier_voxels_looked_at_are_given_up_after_the_nth_arrival(
    make_stack: StackFactory,
) -> None:
    # An unknown voxel 2 m ahead: its near face neighbour (24, 10, 10) is a frontier voxel
    # whose unknown side the camera looks straight into.
    view = _long_view(make_stack, [(25, 10, 10)])
    tracker = _in_view_tracker(after=2)
    target = _idx(24, 10, 10)
    mask = tracker.update(EYE_VOXEL, EYE_VOXEL, target, _looking(view))
    assert not mask.any()
    mask = tracker.update(EYE_VOXEL, EYE_VOXEL, target, _looking(view))
    # The target's cube as before, and every other face neighbour looked at, on its own.
    assert mask[24, 10, 10]
    for voxel in [(25, 9, 10), (25, 11, 10), (25, 10, 9), (25, 10, 11)]:
        assert mask[voxel], voxel
    # The far neighbour's unknown side faces away, but the line of sight to the unknown voxel
    # crosses no occupied voxel: looked at too.
    assert mask[26, 10, 10]


def test_a_frontier_voxel_not_the_target_counts_on_its_own(make_stack: StackFactory) -> None:
    view = _long_view(make_stack, [(25, 10, 10), (35, 12, 10)])
    tracker = _in_view_tracker(after=2)
    target = _idx(24, 10, 10)
    for _ in range(2):
        mask = tracker.update(EYE_VOXEL, EYE_VOXEL, target, _looking(view))
    for voxel in [(34, 12, 10), (36, 12, 10), (35, 11, 10), (35, 13, 10)]:
        assert mask[voxel], voxel
    # No cube around voxels that were not the target: only the voxels looked at.
    assert not mask[33, 12, 10]
    assert not mask[37, 12, 10]


def test_occluded_far_and_unseen_frontier_voxels_do_not_count(make_stack: StackFactory) -> None:
    wall = [(20, j, k) for j in range(0, 20) for k in range(0, 20) if j < 8]
    view = _long_view(
        make_stack,
        [(25, 10, 10),  # in view: counted
         (25, 4, 10),   # behind the wall (y < 0.8 m at x = 2 m)
         (45, 10, 10),  # 4 m ahead, beyond the reach of 3.5 m
         (2, 10, 10)],  # behind the camera
        wall,
    )
    tracker = _in_view_tracker(after=1)
    mask = tracker.update(EYE_VOXEL, EYE_VOXEL, _idx(24, 10, 10), _looking(view))
    assert mask[24, 10, 10]
    assert not mask[24, 4, 10] and not mask[25, 5, 10]
    assert not mask[44, 10, 10]
    assert not mask[3, 10, 10] and not mask[1, 10, 10]


def test_a_turned_camera_looks_at_other_voxels(make_stack: StackFactory) -> None:
    view = _long_view(make_stack, [(25, 10, 10), (35, 12, 10)])
    tracker = _in_view_tracker(after=1)
    # Looking along -x: nothing ahead but the grid's edge. The target still counts, alone.
    mask = tracker.update(EYE_VOXEL, EYE_VOXEL, _idx(24, 10, 10), _looking(view, np.pi))
    assert mask[24, 10, 10]
    assert np.count_nonzero(mask) == np.count_nonzero(mask[22:27, 8:13, 8:13])
    assert not mask[34, 12, 10]
    # Looking along +x from there, the second voxel's neighbours are looked at.
    mask = tracker.update(EYE_VOXEL, EYE_VOXEL, _idx(24, 10, 10), _looking(view))
    assert mask[34, 12, 10]


def test_looks_count_only_arrivals(make_stack: StackFactory) -> None:
    view = _long_view(make_stack, [(25, 10, 10)])
    tracker = _in_view_tracker(after=1)
    # No previous target, or not arrived: nothing counts.
    assert not tracker.update(EYE_VOXEL, None, None, _looking(view)).any()
    away = _idx(15, 10, 10)
    assert not tracker.update(EYE_VOXEL, away, _idx(24, 10, 10), _looking(view)).any()
    blocked = Observation(0.0, Pose(EYE.copy(), 0.0), np.zeros(3), view, PlanOutcome.BLOCKED)
    assert not tracker.update(EYE_VOXEL, EYE_VOXEL, _idx(24, 10, 10), blocked).any()


def test_without_a_reach_only_the_target_counts(make_stack: StackFactory) -> None:
    """classic-v1's tracker: the camera alone changes nothing."""
    view = _long_view(make_stack, [(25, 10, 10), (35, 12, 10)])
    tracker = GiveUpTracker(after=1, radius_voxels=0, camera=CameraConfig())
    mask = tracker.update(EYE_VOXEL, EYE_VOXEL, _idx(24, 10, 10), _looking(view))
    assert np.count_nonzero(mask) == 1
    assert mask[24, 10, 10]
