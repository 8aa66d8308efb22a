"""Information gain of a camera pose: the unknown volume it would see, by ray casting the map.

Rays leave the camera position on a regular grid of directions covering every azimuth (so one
cast serves every yaw) and the camera's vertical field of view. Each ray is marched in steps of
`step_m` up to the sensor range and stops at the first occupied voxel or the grid's edge; unknown
voxels do not stop it (they may well be free), as in NBVP and AEP. A sample at range r in an
unknown voxel stands for the volume r² dr dΩ of the ray's solid-angle cell, so a column's sum
estimates the unknown volume (m³) visible in that azimuth slice. The gain of a yaw is the sum of
the columns inside the horizontal field of view centred on it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numba
import numpy as np
import numpy.typing as npt

from sim.camera import CameraConfig
from sim.map_view import MapView
from sim.occupancy import VoxelState

FloatArray = npt.NDArray[np.float64]

_UNKNOWN = np.uint8(VoxelState.UNKNOWN)
_OCCUPIED = np.uint8(VoxelState.OCCUPIED)


@dataclass(frozen=True)
class RayGrid:
    """The ray directions of one cast.

    Attributes:
        directions: (E, A, 3) unit vectors, E elevations by A azimuths.
        azimuths: (A,) azimuth of each column, rad, 0 .. 2 pi.
        solid_angles: (E,) solid angle of one ray's cell at each elevation, sr.
        window: columns inside the horizontal field of view (odd, centred on a yaw).
    """

    directions: FloatArray
    azimuths: FloatArray
    solid_angles: FloatArray
    window: int

    @classmethod
    def for_camera(cls, camera: CameraConfig, angle_step_deg: float) -> RayGrid:
        step = np.radians(angle_step_deg)
        columns = max(round(float(2.0 * np.pi / step)), 1)
        d_az = 2.0 * np.pi / columns
        azimuths = np.arange(columns) * d_az
        half_v = np.radians(camera.fov_v_deg) / 2.0
        rows = max(int(np.ceil(2.0 * half_v / step)), 1)
        d_el = 2.0 * half_v / rows
        elevations = -half_v + (np.arange(rows) + 0.5) * d_el
        # Exact solid angle of each (d_az x d_el) cell: d_az * (sin(top) - sin(bottom)).
        solid = d_az * (np.sin(elevations + d_el / 2.0) - np.sin(elevations - d_el / 2.0))
        ce, se = np.cos(elevations)[:, None], np.sin(elevations)[:, None]
        dirs = np.stack([ce * np.cos(azimuths)[None, :], ce * np.sin(azimuths)[None, :],
                         np.broadcast_to(se, (rows, columns))], axis=-1)
        half_h = np.radians(camera.fov_h_deg) / 2.0
        window = 2 * int(np.floor(half_h / d_az + 1e-9)) + 1
        return cls(np.ascontiguousarray(dirs, dtype=np.float64),
                   np.asarray(azimuths, dtype=np.float64),
                   np.asarray(solid, dtype=np.float64), min(window, columns))


@numba.njit(cache=True)
def _column_gains(
    state: npt.NDArray[np.uint8],
    origin: FloatArray,
    voxel_size: float,
    position: FloatArray,
    directions: FloatArray,
    solid_angles: FloatArray,
    step_m: float,
    min_range_m: float,
    max_range_m: float,
) -> FloatArray:
    """(A,) unknown volume (m³) seen in each azimuth column from `position` (world, (3,)).

    state: (nx, ny, nz) uint8 voxel states; directions: (E, A, 3); solid_angles: (E,).
    """
    nx, ny, nz = state.shape
    rows, cols = directions.shape[0], directions.shape[1]
    out = np.zeros(cols)
    n_steps = int(np.floor((max_range_m - min_range_m) / step_m))
    for e in range(rows):
        w = solid_angles[e] * step_m
        for a in range(cols):
            dx, dy, dz = directions[e, a, 0], directions[e, a, 1], directions[e, a, 2]
            acc = 0.0
            for s in range(n_steps):
                r = min_range_m + (s + 0.5) * step_m
                i = int(np.floor((position[0] + r * dx - origin[0]) / voxel_size))
                j = int(np.floor((position[1] + r * dy - origin[1]) / voxel_size))
                k = int(np.floor((position[2] + r * dz - origin[2]) / voxel_size))
                if i < 0 or j < 0 or k < 0 or i >= nx or j >= ny or k >= nz:
                    break
                v = state[i, j, k]
                if v == _OCCUPIED:
                    break
                if v == _UNKNOWN:
                    acc += r * r * w
            out[a] += acc
    return out


@dataclass(frozen=True)
class ViewGain:
    """The best yaw of a position and the gain there (m³)."""

    yaw: float
    gain: float


class GainEvaluator:
    """Unknown volume a camera would see from a pose, on the current map.

    Args:
        camera: the camera model (field of view, range).
        angle_step_deg: angular spacing of the rays.
        step_m: marching step along a ray; the map's voxel size is a natural choice.
        max_range_m: gain range; the camera's range when None.
    """

    # What closed surface gaps are filled with for this gain's rays
    # (`planners.surface_gaps`): for unknown volume, an occupied voxel is just a stop.
    gap_fill: ClassVar[int] = VoxelState.OCCUPIED

    def __init__(self, camera: CameraConfig, angle_step_deg: float, step_m: float,
                 max_range_m: float | None = None) -> None:
        self.camera = camera
        self.rays = RayGrid.for_camera(camera, angle_step_deg)
        self.step_m = step_m
        self.min_range_m = camera.min_range_m
        self.max_range_m = camera.max_range_m if max_range_m is None else max_range_m
        self.evaluations = 0

    def columns(self, view: MapView, position: npt.ArrayLike,
                state: npt.NDArray[np.uint8] | None = None) -> FloatArray:
        """(A,) unknown volume per azimuth column around `position` (world (3,)).

        Args:
            state: (nx, ny, nz) voxel states to cast through instead of the view's (the same
                grid, e.g. with narrow gaps in occupied surfaces closed).
        """
        self.evaluations += 1
        return _column_gains(view.state if state is None else state,
                             np.asarray(view.origin, dtype=np.float64),
                             float(view.voxel_size), np.asarray(position, dtype=np.float64),
                             self.rays.directions, self.rays.solid_angles, self.step_m,
                             self.min_range_m, self.max_range_m)

    def window_sums(self, columns: FloatArray) -> FloatArray:
        """(A,) gain of the yaw at each column's azimuth (circular window sums)."""
        half = self.rays.window // 2
        padded = np.concatenate([columns[-half:], columns, columns[:half]]) if half else columns
        c = np.concatenate([[0.0], np.cumsum(padded)])
        return c[self.rays.window:] - c[:-self.rays.window]

    def at_yaw(self, columns: FloatArray, yaw: float) -> float:
        """Gain of looking along `yaw` (rad): the window at the nearest column."""
        d_az = 2.0 * np.pi / len(columns)
        col = int(np.round((yaw % (2.0 * np.pi)) / d_az)) % len(columns)
        return float(self.window_sums(columns)[col])

    def best(self, columns: FloatArray) -> ViewGain:
        """The yaw with the highest gain (lowest azimuth on ties)."""
        sums = self.window_sums(columns)
        col = int(np.argmax(sums))
        yaw = float(self.rays.azimuths[col])
        return ViewGain(yaw if yaw <= np.pi else yaw - 2.0 * np.pi, float(sums[col]))

    def gain(self, view: MapView, position: npt.ArrayLike, yaw: float) -> float:
        """Gain (m³) of the pose (position, yaw)."""
        return self.at_yaw(self.columns(view, position), yaw)

    def best_view(self, view: MapView, position: npt.ArrayLike,
                  state: npt.NDArray[np.uint8] | None = None) -> ViewGain:
        """Best yaw and its gain at `position`; `state` as in `columns`."""
        return self.best(self.columns(view, position, state))
