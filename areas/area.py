"""The Area type: a scene to explore, with its ground truth.

Frames and units are those of `docs/conventions.md`: world frame, z up, metres, yaw in radians
about +z measured from +x.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from areas.surface_cloud import SurfaceCloud

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class StartPose:
    """Where the vehicle starts.

    Attributes:
        position: (3,) metres, world frame.
        yaw: radians about +z.
    """

    position: FloatArray
    yaw: float


@dataclass(frozen=True)
class AreaInfo:
    """Descriptive statistics of an area (the paper's Table 1 columns)."""

    title: str
    rooms: int | None
    levels: int
    complexity: str
    indoor: bool


@dataclass(eq=False)
class Area:
    """A scene: a triangle mesh, its bounds, where to start and how long to explore.

    Attributes:
        name: registry key, lower case (``"maze"``).
        vertices: (V, 3) float64 metres, world frame.
        triangles: (F, 3) int32 indices into ``vertices``.
        bounds_min: (3,) lower corner of the explorable box; the occupancy grid starts here.
        bounds_max: (3,) upper corner.
        start: start pose, with clearance of at least the vehicle radius.
        plateau_s: exploration plateau time in simulated seconds.
        voxel_size: occupancy voxel edge in metres for this area.
        info: Table 1 statistics.
        cache_key: for generated areas, ``name-g<generator version>-s<seed>``: names the
            ground-truth cache file; None for imported areas (the content hash names it).
    """

    name: str
    vertices: FloatArray
    triangles: npt.NDArray[np.int32]
    bounds_min: FloatArray
    bounds_max: FloatArray
    start: StartPose
    plateau_s: float
    voxel_size: float
    info: AreaInfo
    cache_key: str | None = None
    _hash: str | None = field(default=None, repr=False)

    @property
    def extent(self) -> FloatArray:
        """(3,) size of the explorable box in metres."""
        return self.bounds_max - self.bounds_min

    @property
    def grid_shape(self) -> tuple[int, int, int]:
        """Number of occupancy voxels along x, y, z covering the bounds."""
        n = np.ceil(self.extent / self.voxel_size - 1e-9).astype(int)
        return int(n[0]), int(n[1]), int(n[2])

    @property
    def content_hash(self) -> str:
        """SHA-256 of the geometry, bounds, start and voxel size: the ground-truth cache key."""
        if self._hash is None:
            h = hashlib.sha256()
            for arr in (self.vertices, self.triangles, self.bounds_min, self.bounds_max,
                        self.start.position):
                h.update(np.ascontiguousarray(arr).tobytes())
            h.update(np.float64(self.start.yaw).tobytes())
            h.update(np.float64(self.voxel_size).tobytes())
            self._hash = h.hexdigest()
        return self._hash


@dataclass(frozen=True)
class GroundTruth:
    """What a perfect exploration of an area can observe.

    "Reachable" and "observable" follow one rule, the planners' (`areas.observability`): the
    vehicle's centre keeps the safety radius from every blocked voxel's cube.

    Attributes:
        observable: (nx, ny, nz) bool on the area's occupancy grid: the free voxels a camera on
            the vehicle can see from where it can fly, plus the surface layer those voxels touch.
        surface: dense samples of the perceivable surfaces (N points, metres), held packed;
            ``surface_points`` decodes them all, ``surface.sample(n)`` a fixed subsample.
        voxel_size: edge of the ``observable`` voxels in metres.
        free_volume_m3: free space 6-connected to the start, m³ (what a point could reach).
        reachable_volume_m3: the part of it the vehicle's centre can reach, m³.
        observable_free_m3: free space the camera can see from there, m³ (the free part of
            ``observable``); ``free_volume_m3`` minus this is free space no run can observe,
            behind openings narrower than the vehicle or out of the camera's reach.
    """

    observable: npt.NDArray[np.bool_]
    surface: SurfaceCloud
    voxel_size: float
    free_volume_m3: float = 0.0
    reachable_volume_m3: float = 0.0
    observable_free_m3: float = 0.0

    @property
    def surface_points(self) -> npt.NDArray[np.float32]:
        """(N, 3) float32: every surface sample, decoded afresh on each access (hold the result)."""
        return self.surface.points()

    @property
    def unobservable_free_m3(self) -> float:
        """Free space connected to the start that no run can observe, m³."""
        return max(0.0, self.free_volume_m3 - self.observable_free_m3)

    @property
    def observable_volume_m3(self) -> float:
        return float(np.count_nonzero(self.observable)) * self.voxel_size**3
