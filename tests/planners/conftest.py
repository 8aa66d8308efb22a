"""Maps made by hand for the planning-service tests."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import numpy.typing as npt
import pytest

from sim.map_view import MappingStack

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


@pytest.fixture
def make_stack() -> StackFactory:
    return stack_from_state
