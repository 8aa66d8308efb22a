"""SplatPlanner on maps made by hand: normals, flight times, and the choice between a big and a
small frontier patch at equal distances."""

from __future__ import annotations

import numpy as np

from planners.registry import make
from planners.splat import SplatConfig, SplatPlanner
from planners.splat_features import flight_time, frontier_normals
from sim.camera import CameraConfig
from sim.geometry import Pose
from sim.interface import Observation, PlannerContext, PlanOutcome
from sim.occupancy import VoxelState
from sim.vehicle import VehicleLimits
from tests.planners.conftest import StackFactory

VOXEL = 0.1
SAFETY = 0.45
# A closed 5 x 3 x 1.9 m room (x 0.5-5.5 m) between two unknown ends: the whole +x end face
# is unknown (a big frontier patch), the -x end only through a 0.4 x 0.4 m window (a small one),
# 2.5 m from the room's centre; the vehicle stands a voxel nearer the small one (its viewpoint
# 0.4 m away, the big one's 0.5 m), so only the patches' sizes can favour the big one.
SHAPE = (60, 40, 25)
CENTRE = np.array([2.95, 2.05, 1.25])


def _room_state() -> np.ndarray:
    state = np.full(SHAPE, VoxelState.OCCUPIED, dtype=np.uint8)
    state[5:55, 5:35, 3:22] = VoxelState.FREE
    state[55:60, 5:35, 3:22] = VoxelState.UNKNOWN
    state[0:5, 18:22, 10:14] = VoxelState.UNKNOWN
    return state


def _context(seed: int = 0) -> PlannerContext:
    return PlannerContext(
        area="handmade", bounds_min=np.zeros(3), bounds_max=np.array(SHAPE) * VOXEL,
        start=Pose(CENTRE.copy(), 0.0), limits=VehicleLimits(), safety_radius_m=SAFETY,
        camera=CameraConfig(), rng=np.random.default_rng(seed),
    )


def test_registered() -> None:
    planner = make("splatplanner-v1")
    assert isinstance(planner, SplatPlanner)
    config = make("splatplanner-v1", {"sigma_position_m": 0.5}).config
    assert isinstance(config, SplatConfig)
    assert config.sigma_position_m == 0.5


def test_normals_point_into_the_unknown(make_stack: StackFactory) -> None:
    view = make_stack(_room_state(), VOXEL, SAFETY).view()
    big = np.argwhere(view.frontier[50:60])
    big[:, 0] += 50
    normals = frontier_normals(view, big)
    assert len(big) > 300
    np.testing.assert_allclose(normals, np.tile([1.0, 0.0, 0.0], (len(big), 1)))
    small = np.argwhere(view.frontier[:10])
    assert 0 < len(small) < 30
    assert np.all(frontier_normals(view, small)[:, 0] < -0.7)


def test_flight_time_is_a_trapezoid() -> None:
    # 1.5 m/s after 0.6 s at 2.5 m/s²: 0.45 m to reach full speed, as much to stop.
    assert flight_time(np.array([0.9]), 1.5, 2.5) == np.float64(1.2)
    np.testing.assert_allclose(flight_time(np.array([2.4]), 1.5, 2.5), 1.2 + 1.5 / 1.5)
    np.testing.assert_allclose(flight_time(np.array([0.225]), 1.5, 2.5), 2 * np.sqrt(0.09))
    assert flight_time(np.array([0.9, 0.9]), 1.5, 2.5) == 2 * 1.2


def test_chooses_the_big_frontier_patch(make_stack: StackFactory) -> None:
    view = make_stack(_room_state(), VOXEL, SAFETY).view()
    here = view.world_to_index(CENTRE[None])[0]
    assert view.traversable[tuple(here)]
    planner = make("splatplanner")
    planner.reset(_context())
    plan = planner.plan(Observation(0.0, Pose(CENTRE.copy(), np.pi), np.zeros(3), view,
                                    PlanOutcome.NONE))
    assert not plan.done, plan.info
    assert plan.info["mode"] == "splat", plan.info
    final = plan.waypoints[-1]
    # It stands on the big patch's side, facing +x.
    assert final[0] > CENTRE[0]
    assert abs(np.angle(np.exp(1j * final[3]))) < np.radians(10.0)


def test_small_patch_alone_is_still_chosen(make_stack: StackFactory) -> None:
    """With the big end closed, the window's few voxels are still a goal (density above the
    authors' 0.01 floor)."""
    state = _room_state()
    state[55:60] = VoxelState.OCCUPIED
    view = make_stack(state, VOXEL, SAFETY).view()
    planner = SplatPlanner(SplatConfig())
    planner.reset(_context())
    plan = planner.plan(Observation(0.0, Pose(CENTRE.copy(), 0.0), np.zeros(3), view,
                                    PlanOutcome.NONE))
    assert not plan.done, plan.info
    assert plan.info["mode"] == "splat", plan.info
    final = plan.waypoints[-1]
    assert final[0] < CENTRE[0]
    assert abs(abs(final[3]) - np.pi) < np.radians(10.0)


def test_finishes_without_frontier(make_stack: StackFactory) -> None:
    state = _room_state()
    state[state == VoxelState.UNKNOWN] = VoxelState.OCCUPIED
    view = make_stack(state, VOXEL, SAFETY).view()
    planner = make("splatplanner")
    planner.reset(_context())
    plan = planner.plan(Observation(0.0, Pose(CENTRE.copy(), 0.0), np.zeros(3), view,
                                    PlanOutcome.NONE))
    assert plan.done
