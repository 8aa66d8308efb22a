"""The map as planners see it: read-only occupancy, frontiers, traversability and how well each
surface voxel has been measured.

`MappingStack` owns the occupancy map, the surface observation layers and the trackers that
follow the map; `MapView` is the read-only
face handed to planners. Trackers are refreshed lazily, when a planner first asks.
"""

from __future__ import annotations

from functools import cached_property

import numpy as np
import numpy.typing as npt

from sim.clearance import TraversabilityTracker
from sim.frontiers import FrontierCluster, FrontierTracker
from sim.occupancy import OccupancyConfig, OccupancyMap, VoxelState
from sim.surface import SurfaceObservations

__all__ = ["FrontierCluster", "MapView", "MappingStack"]

BoolGrid = npt.NDArray[np.bool_]


class MappingStack:
    """An occupancy map, its surface observation layers, and the frontier and traversability
    trackers that follow it."""

    def __init__(
        self,
        origin: npt.ArrayLike,
        shape: tuple[int, int, int],
        voxel_size: float,
        safety_radius_m: float,
        config: OccupancyConfig | None = None,
    ) -> None:
        self.occupancy = OccupancyMap(origin, shape, voxel_size, config or OccupancyConfig())
        self.surface = SurfaceObservations(self.occupancy)
        self.frontiers = FrontierTracker(self.occupancy)
        self.traversability = TraversabilityTracker(self.occupancy, safety_radius_m)

    def view(self) -> MapView:
        """A read-only snapshot-in-time view; valid until the next integration."""
        return MapView(self)


class MapView:
    """Read-only access to the map for one planning call.

    Grid frame: voxel (i, j, k) spans origin + (i, j, k) * voxel_size to + voxel_size, world metres.
    """

    def __init__(self, stack: MappingStack) -> None:
        self._stack = stack
        occ = stack.occupancy
        self.origin = occ.origin
        self.voxel_size = occ.voxel_size
        self.shape = occ.shape
        self.state = occ.state

    @cached_property
    def free(self) -> BoolGrid:
        """(nx, ny, nz) True on known free voxels."""
        mask = self.state == VoxelState.FREE
        mask.setflags(write=False)
        return mask

    @cached_property
    def occupied(self) -> BoolGrid:
        """(nx, ny, nz) True on occupied voxels."""
        mask = self.state == VoxelState.OCCUPIED
        mask.setflags(write=False)
        return mask

    @cached_property
    def traversable(self) -> BoolGrid:
        """(nx, ny, nz) True where the vehicle centre may be: known free, its centre the safety
        radius or more from every point of every unknown or occupied voxel (`sim.clearance`)."""
        self._stack.traversability.update()
        return self._stack.traversability.traversable

    @cached_property
    def frontier(self) -> BoolGrid:
        """(nx, ny, nz) True on frontier voxels (free, next to unknown)."""
        self._stack.frontiers.update()
        return self._stack.frontiers.frontier

    @property
    def surface_weight(self) -> npt.NDArray[np.uint8]:
        """(nx, ny, nz) uint8: TSDF-fused depth frames with a return in the voxel (the surface's
        TSDF weight), saturating at 255 (`sim/surface.py`)."""
        return self._stack.surface.weight

    @property
    def surface_directions(self) -> npt.NDArray[np.uint8]:
        """(nx, ny, nz) uint8 bit mask: bit b set when the surface in the voxel was seen from
        horizontal sector b (45 degrees each, from +x counter-clockwise, voxel to camera)."""
        return self._stack.surface.directions

    @property
    def surface_observations(self) -> SurfaceObservations:
        """The underlying surface layers, for framework code that follows their changes."""
        return self._stack.surface

    @property
    def occupancy_map(self) -> OccupancyMap:
        """The underlying map, for framework code that follows its changes (`subscribe`)."""
        return self._stack.occupancy

    def frontier_clusters(self, min_size: int = 5) -> list[FrontierCluster]:
        """Connected frontier clusters with at least `min_size` voxels."""
        return self._stack.frontiers.clusters(min_size)

    def world_to_index(self, points: npt.ArrayLike) -> npt.NDArray[np.int64]:
        """(..., 3) world points to voxel indices (possibly outside the grid)."""
        return self._stack.occupancy.world_to_index(points)

    def index_to_world(self, idx: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """(..., 3) voxel indices to their centres in world metres."""
        return self._stack.occupancy.index_to_world(idx)

    def in_bounds(self, idx: npt.ArrayLike) -> BoolGrid:
        return self._stack.occupancy.in_bounds(idx)
