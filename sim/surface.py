"""How well each voxel's surface has been measured: TSDF weight and viewing directions.

Reconstruction-driven planners (ESM-Recon) rank views by how poorly the surface they would see
has been measured so far. The TSDF holds that in its integration weights, but in its own sparse
voxel blocks; this layer keeps the same quantity on the occupancy grid, where planners look:

- ``weight`` (nx, ny, nz) uint8: the number of TSDF-fused depth frames with a return inside the
  voxel, saturating at 255. With the TSDF's unit weight per frame this is the weight of the
  surface there.
- ``directions`` (nx, ny, nz) uint8 bit mask: bit b is set once some such frame saw the voxel
  from horizontal azimuth sector b, ``b = floor((atan2(cy - vy, cx - vx) mod 2 pi) / (pi / 4))``:
  eight sectors of 45 degrees of the direction from the voxel centre to the camera, sector 0
  starting at +x, counter-clockwise (`direction_sector`).

Both are updated only by the frames fused into the TSDF. They have their own subscriptions
(`subscribe`), apart from the occupancy map's, so that copies of the map (the planner sandbox)
follow them without making the frontier and clearance trackers redo boxes whose states did not
change.
"""

from __future__ import annotations

import math
import weakref

import numba
import numpy as np
import numpy.typing as npt

from sim.geometry import FloatArray
from sim.occupancy import DirtyBoxSubscription, IndexBox, OccupancyMap

SECTORS = 8
WEIGHT_MAX = 255

ByteGrid = npt.NDArray[np.uint8]


@numba.njit(cache=True, inline="always")
def _sector(dx: float, dy: float) -> int:
    angle = math.atan2(dy, dx)
    if angle < 0.0:
        angle += 2.0 * math.pi
    return min(int(angle / (2.0 * math.pi / SECTORS)), SECTORS - 1)


def direction_sector(dx: npt.ArrayLike, dy: npt.ArrayLike) -> npt.NDArray[np.int64]:
    """Sector (0..7) of the horizontal direction (dx, dy), voxel to camera; see the module."""
    angle = np.mod(np.arctan2(np.asarray(dy, dtype=np.float64), np.asarray(dx, dtype=np.float64)),
                   2.0 * np.pi)
    return np.minimum((angle / (2.0 * np.pi / SECTORS)).astype(np.int64), SECTORS - 1)


@numba.njit(cache=True)
def _observe(camera: FloatArray, points: FloatArray, grid_origin: FloatArray, voxel_size: float,
             weight: ByteGrid, directions: ByteGrid, stamp: npt.NDArray[np.int64], frame: int,
             box: npt.NDArray[np.int64]) -> None:
    nx, ny, nz = weight.shape
    for p in range(points.shape[0]):
        fi = (points[p, 0] - grid_origin[0]) / voxel_size
        fj = (points[p, 1] - grid_origin[1]) / voxel_size
        fk = (points[p, 2] - grid_origin[2]) / voxel_size
        if not (math.isfinite(fi) and math.isfinite(fj) and math.isfinite(fk)):
            continue
        i, j, k = math.floor(fi), math.floor(fj), math.floor(fk)
        if i < 0 or j < 0 or k < 0 or i >= nx or j >= ny or k >= nz:
            continue
        flat = (i * ny + j) * nz + k
        # One frame adds at most one to a voxel's weight, however many pixels land in it; the
        # sector depends on the voxel and the camera alone, so its first pixel sets it too.
        if stamp[flat] == frame:
            continue
        stamp[flat] = frame
        if weight[i, j, k] < WEIGHT_MAX:
            weight[i, j, k] += 1
        cx = grid_origin[0] + (i + 0.5) * voxel_size
        cy = grid_origin[1] + (j + 0.5) * voxel_size
        directions[i, j, k] |= np.uint8(1 << _sector(camera[0] - cx, camera[1] - cy))
        box[0] = min(box[0], i)
        box[1] = min(box[1], j)
        box[2] = min(box[2], k)
        box[3] = max(box[3], i)
        box[4] = max(box[4], j)
        box[5] = max(box[5], k)


class SurfaceObservations:
    """The weight and direction layers over an occupancy map's grid (see the module)."""

    def __init__(self, occupancy: OccupancyMap) -> None:
        self._occupancy = occupancy
        self._weight = np.zeros(occupancy.shape, dtype=np.uint8)
        self._directions = np.zeros(occupancy.shape, dtype=np.uint8)
        self._stamp: npt.NDArray[np.int64] | None = None  # allocated by the first `observe`
        self._frame = 0
        self._subscriptions: weakref.WeakSet[DirtyBoxSubscription] = weakref.WeakSet()

    @property
    def weight(self) -> ByteGrid:
        """(nx, ny, nz) uint8 surface weight, a read-only view."""
        view = self._weight.view()
        view.setflags(write=False)
        return view

    @property
    def directions(self) -> ByteGrid:
        """(nx, ny, nz) uint8 bit mask of the sectors the surface was seen from, read-only."""
        view = self._directions.view()
        view.setflags(write=False)
        return view

    def observe(self, camera: npt.ArrayLike, points: npt.ArrayLike) -> IndexBox | None:
        """Record one fused frame: `points` (N, 3) are its surface returns, world metres, seen
        from `camera` (3,). Returns the box of voxels it touched (also sent to subscribers)."""
        if self._stamp is None:
            self._stamp = np.full(self._weight.size, -1, dtype=np.int64)
        self._frame += 1
        box = np.array([np.iinfo(np.int64).max] * 3 + [-1] * 3, dtype=np.int64)
        _observe(np.ascontiguousarray(camera, dtype=np.float64).reshape(3),
                 np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3),
                 np.ascontiguousarray(self._occupancy.origin), self._occupancy.voxel_size,
                 self._weight, self._directions, self._stamp, self._frame, box)
        if box[3] < 0:
            return None
        changed = IndexBox((int(box[0]), int(box[1]), int(box[2])),
                           (int(box[3]) + 1, int(box[4]) + 1, int(box[5]) + 1))
        for sub in self._subscriptions:
            sub.merge(changed)
        return changed

    def subscribe(self) -> DirtyBoxSubscription:
        """A new box accumulating the voxels either layer changes from now on (weakly held)."""
        sub = DirtyBoxSubscription()
        self._subscriptions.add(sub)
        return sub

    def load(self, weight: ByteGrid, directions: ByteGrid, box: IndexBox) -> None:
        """Copy `box` of both layers from elsewhere (a mirror of the runner's map)."""
        region = box.slices()
        self._weight[region] = weight[region]
        self._directions[region] = directions[region]
        for sub in self._subscriptions:
            sub.merge(box)
