"""Maps made by hand for the planning-service tests."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import numpy.typing as npt
import pytest

from sim.camera import CameraConfig
from sim.geometry import Pose
from sim.interface import PlannerContext
from sim.map_view import MappingStack, MapView
from sim.occupancy import VoxelState
from sim.vehicle import VehicleLimits

StackFactory = Callable[[npt.NDArray[np.uint8], float, float], MappingStack]


def stack_from_state(state: npt.NDArray[np.uint8], voxel_size: float,
                     safety_radius_m: float) -> MappingStack:
    """A mapping stack whose occupancy states are `state` (nx, ny, nz), trackers up to date.

    The states are written directly (the map has no public setter: only rays change it).
    """
    stack = MappingStack(np.zeros(3), state.shape, voxel_size, safety_radius_m)
    stack.occupancy._state[...] = state
    stack.frontiers.full_recompute()
    stack.traversability.full_recompute()
    return stack


# A 6 x 4 x 2.5 m area mapped at 0.1 m, for the tests of the tree planners.
HANDMADE_VOXEL = 0.1
HANDMADE_SHAPE = (60, 40, 25)


def handmade_context(indoor: bool = True) -> PlannerContext:
    """The context of a planner in the hand-made area (`HANDMADE_SHAPE`), seeded 0."""
    return PlannerContext(area="handmade", bounds_min=np.zeros(3),
                          bounds_max=np.array(HANDMADE_SHAPE) * HANDMADE_VOXEL,
                          start=Pose(np.ones(3), 0.0), limits=VehicleLimits(),
                          safety_radius_m=0.45, camera=CameraConfig(),
                          rng=np.random.default_rng(0), indoor=indoor)


def open_box_view() -> MapView:
    """The hand-made area: a known-free box in unknown space, so that every view near its
    faces has something to gain."""
    state = np.zeros(HANDMADE_SHAPE, dtype=np.uint8)
    state[5:55, 5:35, 3:22] = VoxelState.FREE
    return stack_from_state(state, HANDMADE_VOXEL, 0.45).view()


@pytest.fixture
def make_stack() -> StackFactory:
    return stack_from_state
