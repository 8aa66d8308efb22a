"""The planner process's copy of the map, refreshed from shared memory before each call.

The runner writes the occupancy states and the surface observation layers into a shared,
read-only (for the planner) memory map and sends the boxes that changed; the mirror copies those
boxes and tells its frontier and traversability trackers, which then update only there, as they
do in the runner.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from sim.clearance import TraversabilityTracker
from sim.frontiers import FrontierTracker
from sim.map_view import MapView
from sim.occupancy import IndexBox, OccupancyMap, VoxelState
from sim.surface import SurfaceObservations


class MirrorMap(OccupancyMap):
    """An occupancy map whose states come from elsewhere (no ray integration here)."""

    def load(self, source: npt.NDArray[np.uint8], box: IndexBox) -> None:
        """Copy `source[box]` (the runner's states) in and report the box as changed."""
        region = box.slices()
        before = int(np.count_nonzero(self._state[region] != VoxelState.UNKNOWN))
        self._state[region] = source[region]
        after = int(np.count_nonzero(self._state[region] != VoxelState.UNKNOWN))
        self._known += after - before
        for sub in self._subscriptions:
            sub.merge(box)


class MirrorStack:
    """The `MappingStack` counterpart in the planner process."""

    def __init__(self, origin: npt.ArrayLike, shape: tuple[int, int, int], voxel_size: float,
                 safety_radius_m: float) -> None:
        self.occupancy = MirrorMap(origin, shape, voxel_size)
        self.surface = SurfaceObservations(self.occupancy)
        self.frontiers = FrontierTracker(self.occupancy)
        self.traversability = TraversabilityTracker(self.occupancy, safety_radius_m)

    def view(self) -> MapView:
        return MapView(self)  # type: ignore[arg-type]  # same attributes as a MappingStack
