"""classic-v3: the path shortcut from the vehicle's exact position, on a map made by hand where
the leg from a point a hundredth of a voxel off its voxel's centre grazes a voxel that the leg
from the centre only touches at a corner."""

from __future__ import annotations

import numpy as np

from planners.api import PlannerContext
from planners.classic import ClassicPlanner, ClassicV2, ClassicV2Config, ClassicV3, ClassicV3Config
from planners.search import DistanceField, segment_clear, shortcut
from planners.waypoints import path_waypoints, shortcut_from_position
from sim.camera import CameraConfig
from sim.geometry import Pose
from sim.interface import Observation, PlanOutcome
from sim.map_view import MapView
from sim.occupancy import VoxelState
from sim.search_checks import plan_is_clear
from sim.vehicle import VehicleLimits
from tests.planners.conftest import StackFactory

VOXEL = 0.1
OWN = np.array([9, 13, 15])
GOAL = np.array([16, 20, 15])
# Off the own voxel's centre by a hundredth of a voxel on x and y, as a vehicle at rest is.
OFF_CENTRE = (OWN + 0.5 + np.array([0.01, -0.01, 0.0])) * VOXEL


def _view(make_stack: StackFactory) -> MapView:
    """Free space with one occupied voxel at (15, 15, 15); safety radius 2 voxels. The straight
    line from OWN's centre to GOAL's runs at 45 degrees through voxel corners beside the
    obstacle's margin."""
    state = np.full((30, 30, 30), VoxelState.FREE, dtype=np.uint8)
    state[15, 15, 15] = VoxelState.OCCUPIED
    return make_stack(state, VOXEL, 0.2).view()


def _raw_path(view: MapView) -> np.ndarray:
    """The search's voxel path from OWN to GOAL."""
    goals = np.zeros(view.shape, dtype=np.bool_)
    goals[tuple(GOAL)] = True
    field = DistanceField(view.traversable, OWN, VOXEL, goals=goals)
    assert field.nearest_goal is not None
    return field.path_to(field.nearest_goal)


def test_the_map_grazes_from_off_centre_only(make_stack: StackFactory) -> None:
    view = _view(make_stack)
    t = view.traversable
    assert segment_clear(t, OWN + 0.5, GOAL + 0.5)
    assert not segment_clear(t, OFF_CENTRE / VOXEL, GOAL + 0.5)
    np.testing.assert_array_equal(shortcut(_raw_path(view), t), [OWN, GOAL])


def test_from_the_centre_the_shortcut_is_unchanged(make_stack: StackFactory) -> None:
    view = _view(make_stack)
    raw = _raw_path(view)
    centre = (OWN + 0.5) * VOXEL
    np.testing.assert_array_equal(shortcut_from_position(view, raw, centre),
                                  shortcut(raw, view.traversable))


def test_off_centre_the_first_leg_goes_from_the_position(make_stack: StackFactory) -> None:
    view = _view(make_stack)
    raw = _raw_path(view)
    look_at = (GOAL + 0.5) * VOXEL
    # From the shortcut made at the centre, the first waypoint is the own voxel's centre.
    old = path_waypoints(view, shortcut(raw, view.traversable), OFF_CENTRE, look_at)
    np.testing.assert_allclose(old[0, :3], (OWN + 0.5) * VOXEL)
    # From the position: a voxel of the path beyond the own one, reached by a clear leg.
    path = shortcut_from_position(view, raw, OFF_CENTRE)
    np.testing.assert_array_equal(path[0], OWN)
    np.testing.assert_array_equal(path[-1], GOAL)
    assert not np.array_equal(path[1], GOAL)
    assert segment_clear(view.traversable, OFF_CENTRE / VOXEL, path[1] + 0.5)
    new = path_waypoints(view, path, OFF_CENTRE, look_at)
    np.testing.assert_allclose(new[0, :3], (path[1] + 0.5) * VOXEL)
    assert np.linalg.norm(new[0, :3] - OFF_CENTRE) > VOXEL
    # The framework flies every waypoint of it from the position.
    assert plan_is_clear(view.traversable, view.traversable, view.origin, VOXEL, OFF_CENTRE,
                         new[:, :3]) == len(new)


def test_a_path_from_another_voxel_is_left_to_shortcut(make_stack: StackFactory) -> None:
    view = _view(make_stack)
    raw = _raw_path(view)
    elsewhere = OFF_CENTRE + np.array([0.0, -2 * VOXEL, 0.0])
    np.testing.assert_array_equal(shortcut_from_position(view, raw, elsewhere),
                                  shortcut(raw, view.traversable))


def _plan(view: MapView, cls: type[ClassicPlanner], position: np.ndarray) -> np.ndarray:
    """The waypoints (N, 4) of a first call of a fresh `cls` at `position` (world (3,))."""
    planner = cls(cls.config_model(min_cluster_size=1))
    planner.reset(PlannerContext("handmade", np.zeros(3), np.array(view.shape) * VOXEL,
                                 Pose(position, 0.0), VehicleLimits(), 0.2, CameraConfig(),
                                 np.random.default_rng(0)))
    plan = planner.plan(Observation(0.0, Pose(position, 0.0), np.zeros(3), view,
                                    PlanOutcome.NONE))
    assert not plan.done
    return plan.waypoints


def _frontier_view(make_stack: StackFactory) -> MapView:
    """Free space with one occupied voxel at (15, 15, 15) and a block of unknown at
    (30-31, 30-31, 14-16), its frontier across the obstacle from (12, 16, 15); safety radius 2
    voxels."""
    state = np.full((40, 40, 30), VoxelState.FREE, dtype=np.uint8)
    state[15, 15, 15] = VoxelState.OCCUPIED
    state[30:32, 30:32, 14:17] = VoxelState.UNKNOWN
    return make_stack(state, VOXEL, 0.2).view()


def test_v2_flies_back_to_the_centre_where_v3_flies_on(make_stack: StackFactory) -> None:
    view = _frontier_view(make_stack)
    own = np.array([12, 16, 15])
    centre = (own + 0.5) * VOXEL
    position = (own + 0.5 + np.array([0.01, -0.01, 0.0])) * VOXEL
    v2 = _plan(view, ClassicV2, position)
    np.testing.assert_allclose(v2[0, :3], centre)
    v3 = _plan(view, ClassicV3, position)
    assert np.linalg.norm(v3[0, :3] - centre) >= VOXEL
    assert plan_is_clear(view.traversable, view.traversable, view.origin, VOXEL, position,
                         v3[:, :3]) == len(v3)
    # Both go to the same viewpoint.
    np.testing.assert_allclose(v3[-1], v2[-1])
    # From the centre itself nothing grazes, and the two versions plan alike.
    np.testing.assert_allclose(_plan(view, ClassicV3, centre), _plan(view, ClassicV2, centre))


def test_v3_differs_from_v2_in_one_setting() -> None:
    v2, v3 = ClassicV2Config().model_dump(), ClassicV3Config().model_dump()
    assert {k for k in v2 if v2[k] != v3[k]} == {"shortcut_from_position"}
    assert ClassicV3.config_model is ClassicV3Config
    assert not issubclass(ClassicV3, ClassicV2) and not issubclass(ClassicV2, ClassicV3)
