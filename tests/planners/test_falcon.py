"""FALCON on maps made by hand: the zones of the space decomposition and their connectivity, the
coverage path over them, and one plan."""

from __future__ import annotations

import numpy as np

from planners.falcon import Falcon, FalconConfig
from planners.falcon_costs import Dynamics
from planners.falcon_guidance import coverage_path
from planners.falcon_zones import ZoneGrid
from planners.registry import make
from sim.camera import CameraConfig
from sim.geometry import Pose
from sim.interface import Observation, PlannerContext, PlanOutcome
from sim.occupancy import VoxelState
from sim.vehicle import VehicleLimits
from tests.planners.conftest import StackFactory

VOXEL = 0.1
SAFETY = 0.45
# 10 x 5 x 2 m: two cells of 5 m along x, one layer (2 m high).
SHAPE = (100, 50, 20)
DYN = Dynamics(v_max=1.5, a_max=2.5, vz_max=1.0, yaw_rate=1.0, yaw_acc=2.0)


def _grid() -> ZoneGrid:
    return ZoneGrid(SHAPE, np.zeros(3), VOXEL, cell_size_m=5.0, ccl_step=2, min_free_cells=10,
                    min_unknown_fraction=0.1, clearance_m=SAFETY)


def _walled_state() -> np.ndarray:
    """Free inside a 0.3 m shell, a wall across x = 2.0-2.2 m cutting the first cell in two."""
    state = np.full(SHAPE, VoxelState.OCCUPIED, dtype=np.uint8)
    state[3:97, 3:47, 1:19] = VoxelState.FREE
    state[20:22, :, :] = VoxelState.OCCUPIED
    return state


def test_registered() -> None:
    assert isinstance(make("falcon-v1"), Falcon)
    config = make("falcon", {"cell_size_m": 4.0}).config
    assert isinstance(config, FalconConfig)
    assert config.cell_size_m == 4.0


def test_a_wall_cuts_a_cell_into_two_free_zones(make_stack: StackFactory) -> None:
    view = make_stack(_walled_state(), VOXEL, SAFETY).view()
    zones = _grid().update(view)
    assert not zones.unknown.any()
    assert np.bincount(zones.cell).tolist() == [2, 1]
    left, right = sorted(np.flatnonzero(zones.cell == 0), key=lambda z: zones.centers[z, 0])
    far = int(np.flatnonzero(zones.cell == 1)[0])
    assert zones.centers[left, 0] < 2.0 < zones.centers[right, 0] < 5.0
    # The right part of the first cell touches the second cell across x = 5 m; the wall cuts
    # the left part off.
    assert np.isfinite(zones.distance_m(np.array([right]), np.array([far]))).all()
    assert np.isinf(zones.distance_m(np.array([left]), np.array([far]))).all()
    # Centres are coarse cells of their zone, and the labels find them.
    assert zones.zone_at(view, zones.centers).tolist() == list(range(3))


def test_unknown_zones_join_by_portals_and_holes_are_left_out(make_stack: StackFactory) -> None:
    state = np.full(SHAPE, VoxelState.OCCUPIED, dtype=np.uint8)
    state[3:60, 3:47, 1:19] = VoxelState.FREE
    state[60:97, 3:47, 1:19] = VoxelState.UNKNOWN  # the unexplored end, beyond x = 6 m
    state[5:45, 5:45, 1:19] = VoxelState.OCCUPIED  # a block in the first cell...
    state[10:40, 10:40, 1:19] = VoxelState.UNKNOWN  # ...hiding an unknown pocket
    view = make_stack(state, VOXEL, SAFETY).view()
    zones = _grid().update(view)
    unknown = np.flatnonzero(zones.unknown)
    pocket = [z for z in unknown if zones.centers[z, 0] < 5.0]
    end = [z for z in unknown if zones.centers[z, 0] > 6.0]
    assert len(pocket) == 1 and len(end) == 1
    assert not zones.kept[pocket[0]]
    assert zones.kept[end[0]]
    free = np.flatnonzero(~zones.unknown)
    assert np.isfinite(zones.distance_m(free, np.array([end[0]]))).all()

    # The coverage path leaves the unknown zone for last and never goes to the pocket.
    here = np.array([2.5, 4.6, 1.0])
    path = coverage_path(view, zones, view.state != VoxelState.OCCUPIED, here, np.zeros(3),
                         zones.centers[free], free, DYN, 15.0, 2.0, 12)
    assert path.zone.tolist()[-1] == end[0]
    assert pocket[0] not in path.zone.tolist()
    assert len(path.legs_s) == len(path.zone) == len(free) + 1


def test_unchanged_cells_keep_their_labels(make_stack: StackFactory) -> None:
    grid = _grid()
    stack = make_stack(_walled_state(), VOXEL, SAFETY)
    first = grid.update(stack.view())
    second = grid.update(stack.view())
    np.testing.assert_array_equal(first.labels, second.labels)
    np.testing.assert_array_equal(first.centers, second.centers)


def _room_context() -> PlannerContext:
    return PlannerContext(
        area="handmade", bounds_min=np.zeros(3), bounds_max=np.array(SHAPE) * VOXEL,
        start=Pose(np.array([2.5, 2.5, 1.0]), 0.0), limits=VehicleLimits(),
        safety_radius_m=SAFETY, camera=CameraConfig(), rng=np.random.default_rng(0))


def test_plans_toward_the_unexplored_end(make_stack: StackFactory) -> None:
    state = np.full(SHAPE, VoxelState.OCCUPIED, dtype=np.uint8)
    state[3:70, 3:47, 1:19] = VoxelState.FREE
    state[70:97, 3:47, 1:19] = VoxelState.UNKNOWN
    view = make_stack(state, VOXEL, SAFETY).view()
    planner = make("falcon")
    planner.reset(_room_context())
    here = np.array([2.5, 2.5, 1.0])
    plan = planner.plan(Observation(0.0, Pose(here, 0.0), np.zeros(3), view, PlanOutcome.NONE))
    assert not plan.done, plan.info
    goal = plan.waypoints[-1, :3]
    assert goal[0] > here[0] + 1.0
    idx = view.world_to_index(plan.waypoints[:, :3])
    assert view.traversable[idx[:, 0], idx[:, 1], idx[:, 2]].all()
    assert plan.replan_s == FalconConfig().covered_check_s
