"""classic-v2's parts on maps made by hand: viewpoints that see into the unknown, the starts of
a vehicle the map closed in on, and the search that tries the next pocket; classic-v1 keeps its
settings."""

from __future__ import annotations

import numpy as np
import pytest

from planners.classic import Classic, ClassicConfig, ClassicPlanner, ClassicV2, ClassicV2Config
from planners.search import DistanceField
from planners.viewpoints import ViewpointCandidates, ring_offsets, sees_into_unknown
from planners.waypoints import escape_starts
from sim.map_view import MapView
from sim.occupancy import VoxelState
from sim.search_checks import segment_in_mask
from tests.planners.conftest import StackFactory

VOXEL = 0.1


def _floor_view(make_stack: StackFactory) -> MapView:
    """A 3 x 3 x 1.5 m room over a slab: the slab's interior (k = 0) unknown, its surface layer
    (k = 1) occupied but for a patch of 2 x 2 free voxels at (15-16, 15-16, 1) that grazing
    rays would leave, free above."""
    state = np.full((30, 30, 15), VoxelState.FREE, dtype=np.uint8)
    state[:, :, 0] = VoxelState.UNKNOWN
    state[:, :, 1] = VoxelState.OCCUPIED
    state[15:17, 15:17, 1] = VoxelState.FREE
    return make_stack(state, VOXEL, 0.2).view()


def _viewpoints(view: MapView, into_unknown: bool, min_size: int = 1):  # type: ignore[no-untyped-def]
    cfg = ClassicConfig()
    return ViewpointCandidates(
        view, view.frontier_clusters(min_size),
        ring_offsets(cfg.view_distances_m, cfg.view_height_offsets_m, cfg.view_directions),
        samples_per_cluster=cfg.samples_per_cluster,
        max_elevation_rad=np.radians(cfg.max_view_elevation_deg), max_range_m=5.0,
        into_unknown=into_unknown,
    ).all()


def test_free_floor_voxels_over_the_slab_have_no_viewpoint_into_the_unknown(
    make_stack: StackFactory,
) -> None:
    view = _floor_view(make_stack)
    assert view.frontier[15, 15, 1]
    assert np.count_nonzero(view.frontier) == 4
    # v1: the voxels themselves are in clear sight from the ring around them.
    assert len(_viewpoints(view, into_unknown=False)) > 0
    # The unknown below them lies behind the occupied floor voxels around them from every
    # viewpoint no steeper than 30 degrees.
    assert len(_viewpoints(view, into_unknown=True)) == 0


def test_a_frontier_open_to_the_camera_keeps_its_viewpoints(make_stack: StackFactory) -> None:
    state = np.full((40, 40, 20), VoxelState.FREE, dtype=np.uint8)
    state[25:30, 15:25, 5:15] = VoxelState.UNKNOWN  # a block of unknown in the open
    view = make_stack(state, VOXEL, 0.2).view()
    old = _viewpoints(view, into_unknown=False, min_size=5)
    new = _viewpoints(view, into_unknown=True, min_size=5)
    assert 0 < len(new) <= len(old)
    # Those kept are the ones on the frontier's open side: most of the ring.
    assert len(new) >= len(old) // 2


def test_sees_into_unknown_checks_the_line_to_an_unknown_face_neighbour(
    make_stack: StackFactory,
) -> None:
    view = _floor_view(make_stack)
    target = np.array([[15, 15, 1]], dtype=np.int64)
    # Straight above: the line goes down through the free voxel into the slab.
    assert sees_into_unknown(view, np.array([[15.5, 15.5, 8.5]]), target)[0]
    # At a grazing angle it crosses the occupied floor voxels first.
    assert not sees_into_unknown(view, np.array([[25.5, 15.5, 3.5]]), target)[0]


# -- escape_starts -----------------------------------------------------------------------------


def _box_view(make_stack: StackFactory) -> MapView:
    """Free space with one occupied voxel at (15, 15, 15); safety radius 2 voxels."""
    state = np.full((30, 30, 30), VoxelState.FREE, dtype=np.uint8)
    state[15, 15, 15] = VoxelState.OCCUPIED
    return make_stack(state, VOXEL, 0.2).view()


def test_escape_starts_is_the_own_voxel_when_traversable(make_stack: StackFactory) -> None:
    view = _box_view(make_stack)
    starts = escape_starts(view, np.array([0.55, 0.55, 0.55]), reach=10)
    np.testing.assert_array_equal(starts, [[5, 5, 5]])
    assert starts.dtype == np.int64


def test_escape_starts_lists_flyable_exits_nearest_first(make_stack: StackFactory) -> None:
    view = _box_view(make_stack)
    position = np.array([1.65, 1.55, 1.55])  # voxel (16, 15, 15), beside the obstacle
    assert not view.traversable[16, 15, 15]
    starts = escape_starts(view, position, reach=4)
    assert len(starts) > 0
    assert np.all(view.traversable[starts[:, 0], starts[:, 1], starts[:, 2]])
    eye = position / VOXEL
    distances = np.linalg.norm(starts + 0.5 - eye, axis=1)
    assert np.all(np.diff(distances) >= -1e-9)
    # The nearest voxel whose centre keeps 2 voxels from the obstacle's cube [15, 16).
    np.testing.assert_array_equal(starts[0], [18, 15, 15])
    for cell in starts:
        assert segment_in_mask(view.traversable, view.free, eye, cell + 0.5, True)
    # The far side of the obstacle lies behind it: no leg through the occupied voxel.
    assert not any(c[0] < 15 and c[1] == 15 and c[2] == 15 for c in starts)
    assert np.all(np.abs(starts - [16, 15, 15]) <= 4)


def test_escape_starts_empty_when_nothing_is_in_reach(make_stack: StackFactory) -> None:
    state = np.full((30, 30, 30), VoxelState.UNKNOWN, dtype=np.uint8)
    state[10:12, 10:12, 10:12] = VoxelState.FREE  # too small to be traversable anywhere
    view = make_stack(state, VOXEL, 0.2).view()
    assert escape_starts(view, np.array([1.15, 1.15, 1.15]), reach=10).shape == (0, 3)


# -- the search from several starts ------------------------------------------------------------


def test_search_tries_the_next_pocket() -> None:
    traversable = np.zeros((20, 10, 5), dtype=np.bool_)
    traversable[0:5, :, :] = True  # pocket A: no goal
    traversable[10:20, :, :] = True  # pocket B
    goals = np.zeros_like(traversable)
    goals[18, 5, 2] = True
    starts = np.array([[4, 5, 2], [4, 4, 2], [10, 5, 2]], dtype=np.int64)
    field = ClassicPlanner._search(traversable, starts, VOXEL, goals)
    assert field is not None
    np.testing.assert_array_equal(field.nearest_goal, [18, 5, 2])
    np.testing.assert_array_equal(field.start, [10, 5, 2])


def test_search_gives_the_single_start_its_field_and_none_when_no_pocket_leads_on() -> None:
    traversable = np.zeros((20, 10, 5), dtype=np.bool_)
    traversable[0:5, :, :] = True
    goals = np.zeros_like(traversable)
    goals[18, 5, 2] = True
    one = ClassicPlanner._search(traversable, np.array([[2, 2, 2]]), VOXEL, goals)
    assert isinstance(one, DistanceField) and one.nearest_goal is None
    assert ClassicPlanner._search(traversable, np.array([[2, 2, 2], [3, 3, 3]]), VOXEL,
                                  goals) is None


# -- versions ----------------------------------------------------------------------------------


def test_v1_and_v2_differ_in_the_v2_settings_only() -> None:
    v1, v2 = ClassicConfig().model_dump(), ClassicV2Config().model_dump()
    differ = {k for k in v1 if v1[k] != v2[k]}
    assert differ == {"view_into_unknown", "visited_view_reach_m", "escape_reach_voxels"}
    assert v1["view_into_unknown"] is False
    assert v1["visited_view_reach_m"] is None
    assert v1["escape_reach_voxels"] is None
    assert Classic.config_model is ClassicConfig
    assert ClassicV2.config_model is ClassicV2Config
    assert not issubclass(ClassicV2, Classic) and not issubclass(Classic, ClassicV2)


@pytest.mark.parametrize("cls", [Classic, ClassicV2])
def test_both_versions_plan_on_the_floor_map(make_stack: StackFactory, cls: type) -> None:
    """The only frontier is the floor patch: v1 flies to look at it, v2 sees no viewpoint."""
    from planners.api import PlannerContext
    from sim.camera import CameraConfig
    from sim.geometry import Pose
    from sim.interface import Observation, PlanOutcome
    from sim.vehicle import VehicleLimits

    view = _floor_view(make_stack)
    planner = cls(cls.config_model(min_cluster_size=1))
    here = np.array([0.55, 0.55, 0.75])
    planner.reset(PlannerContext("handmade", np.zeros(3), np.array([3.0, 3.0, 1.5]),
                                 Pose(here, 0.0), VehicleLimits(), 0.2, CameraConfig(),
                                 np.random.default_rng(0)))
    plan = planner.plan(Observation(0.0, Pose(here, 0.0), np.zeros(3), view, PlanOutcome.NONE))
    if cls is Classic:
        assert not plan.done
    else:
        assert plan.done
        assert plan.info["reason"] == "no frontier can be seen from traversable space"
