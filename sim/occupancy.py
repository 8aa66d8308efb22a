"""Probabilistic occupancy grid updated by casting depth rays through it.

Grid convention: voxel (0, 0, 0) has its lower corner at ``origin`` (3,), metres, world frame;
voxel (i, j, k) spans ``origin + [i, j, k] * voxel_size`` to ``origin + [i+1, j+1, k+1] *
voxel_size``. A point on a voxel face belongs to the voxel on its upper side (floor rule).

Each voxel keeps a float32 log-odds value and a uint8 `VoxelState`. A voxel is UNKNOWN until a
ray first touches it; from then on it is OCCUPIED when its log-odds exceed the threshold and FREE
otherwise.

Consumers that derive data from the states (frontiers, clearance) follow changes through
`DirtyBoxSubscription`: every subscription accumulates the bounding box of the voxels whose
state changed since its own last `take()`, so several consumers can be refreshed from the same
integrations at their own pace without sharing or resetting each other's box.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass
from enum import IntEnum

import numba
import numpy as np
import numpy.typing as npt
from pydantic import BaseModel, ConfigDict, Field, model_validator

from sim.geometry import FloatArray

IndexArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]
StateGrid = npt.NDArray[np.uint8]
LogOddsGrid = npt.NDArray[np.float32]


class VoxelState(IntEnum):
    """Value of a voxel in `OccupancyMap.state`."""

    UNKNOWN = 0
    FREE = 1
    OCCUPIED = 2


_UNKNOWN = np.uint8(VoxelState.UNKNOWN)
_FREE = np.uint8(VoxelState.FREE)
_OCCUPIED = np.uint8(VoxelState.OCCUPIED)


class OccupancyConfig(BaseModel):
    """Log-odds sensor model.

    Attributes:
        log_odds_hit: added to the voxel holding a ray's return.
        log_odds_miss: added to every voxel a ray passes through before its end.
        clamp_min: lower bound of the log-odds, so free space can turn occupied again quickly.
        clamp_max: upper bound of the log-odds.
        occupied_threshold: a known voxel is OCCUPIED when its log-odds is > this, else FREE.
        clear_max_range: rays without a return (hit False) carve free space up to their end,
            end voxel included; when False such rays are ignored.
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    log_odds_hit: float = Field(0.85, gt=0.0)
    log_odds_miss: float = Field(-0.4, lt=0.0)
    clamp_min: float = -2.0
    clamp_max: float = 3.5
    occupied_threshold: float = 0.0
    clear_max_range: bool = True

    @model_validator(mode="after")
    def _ordered_bounds(self) -> OccupancyConfig:
        if not self.clamp_min <= self.occupied_threshold < self.clamp_max:
            raise ValueError("need clamp_min <= occupied_threshold < clamp_max")
        return self


@dataclass(frozen=True)
class IndexBox:
    """Half-open box of voxel indices: ``lo[a] <= index[a] < hi[a]`` on each axis a."""

    lo: tuple[int, int, int]
    hi: tuple[int, int, int]

    @property
    def shape(self) -> tuple[int, int, int]:
        return (self.hi[0] - self.lo[0], self.hi[1] - self.lo[1], self.hi[2] - self.lo[2])

    @property
    def size(self) -> int:
        """Number of voxels in the box (0 when empty)."""
        sx, sy, sz = self.shape
        return max(sx, 0) * max(sy, 0) * max(sz, 0)

    def slices(self) -> tuple[slice, slice, slice]:
        """Index the box in a (nx, ny, nz) array."""
        return (
            slice(self.lo[0], self.hi[0]),
            slice(self.lo[1], self.hi[1]),
            slice(self.lo[2], self.hi[2]),
        )

    def union(self, other: IndexBox) -> IndexBox:
        lo = (min(self.lo[0], other.lo[0]), min(self.lo[1], other.lo[1]),
              min(self.lo[2], other.lo[2]))
        hi = (max(self.hi[0], other.hi[0]), max(self.hi[1], other.hi[1]),
              max(self.hi[2], other.hi[2]))
        return IndexBox(lo, hi)

    def expanded(self, margin: int, shape: tuple[int, int, int]) -> IndexBox:
        """The box grown by `margin` voxels on every side, clipped to a grid of `shape`."""
        lo = (max(self.lo[0] - margin, 0), max(self.lo[1] - margin, 0),
              max(self.lo[2] - margin, 0))
        hi = (min(self.hi[0] + margin, shape[0]), min(self.hi[1] + margin, shape[1]),
              min(self.hi[2] + margin, shape[2]))
        return IndexBox(lo, hi)

    @staticmethod
    def full(shape: tuple[int, int, int]) -> IndexBox:
        return IndexBox((0, 0, 0), (int(shape[0]), int(shape[1]), int(shape[2])))


class DirtyBoxSubscription:
    """The box of voxels whose state changed since this subscriber's last `take()`."""

    def __init__(self) -> None:
        self._box: IndexBox | None = None

    def merge(self, box: IndexBox) -> None:
        self._box = box if self._box is None else self._box.union(box)

    def peek(self) -> IndexBox | None:
        return self._box

    def take(self) -> IndexBox | None:
        """The accumulated box (None when nothing changed), then reset."""
        box, self._box = self._box, None
        return box


@numba.njit(cache=True)
def _floor_in(x: float, n: int) -> int:
    """floor(x) clamped to [0, n - 1]."""
    return min(max(math.floor(x), 0), n - 1)


@numba.njit(cache=True)
def _axis_start(a: float, d: float, i: int) -> tuple[int, float, float]:
    """Step sign, t of the first face crossing out of voxel i, t between crossings."""
    if d > 0.0:
        return 1, (i + 1 - a) / d, 1.0 / d
    if d < 0.0:
        return -1, (i - a) / d, -1.0 / d
    return 0, math.inf, math.inf


@numba.njit(cache=True)
def _traverse(
    ax: float, ay: float, az: float, bx: float, by: float, bz: float,
    nx: int, ny: int, nz: int, buf: IndexArray,
) -> tuple[int, bool, int, int, int, int, int, int]:
    """3D-DDA (Amanatides & Woo) of the segment a→b clipped to the grid box.

    a, b: segment ends in grid units, (world - grid origin) / voxel_size; voxel (i, j, k) spans
        [i, i+1) x [j, j+1) x [k, k+1) and the box is [0, nx) x [0, ny) x [0, nz).
    buf: (M,) int64 with M >= nx + ny + nz; receives the flat C-order indices of the in-grid
        voxels the segment visits, in order. When b lies in the grid the last one is floor(b).

    Returns:
        count written, whether the last voxel written is b's voxel, then the i, j, k of the
        first and of the last voxel written (meaningless when count is 0).
    """
    dx = bx - ax
    dy = by - ay
    dz = bz - az
    ex = math.floor(bx)
    ey = math.floor(by)
    ez = math.floor(bz)
    end_in = 0 <= ex < nx and 0 <= ey < ny and 0 <= ez < nz
    end_flat = (ex * ny + ey) * nz + ez
    # Slab clipping to the grid box; t runs from 0 at a to 1 at b.
    t0 = 0.0
    t1 = 1.0
    if dx != 0.0:
        ta = -ax / dx
        tb = (nx - ax) / dx
        t0 = max(t0, min(ta, tb))
        t1 = min(t1, max(ta, tb))
    elif ax < 0.0 or ax >= nx:
        return 0, False, 0, 0, 0, 0, 0, 0
    if dy != 0.0:
        ta = -ay / dy
        tb = (ny - ay) / dy
        t0 = max(t0, min(ta, tb))
        t1 = min(t1, max(ta, tb))
    elif ay < 0.0 or ay >= ny:
        return 0, False, 0, 0, 0, 0, 0, 0
    if dz != 0.0:
        ta = -az / dz
        tb = (nz - az) / dz
        t0 = max(t0, min(ta, tb))
        t1 = min(t1, max(ta, tb))
    elif az < 0.0 or az >= nz:
        return 0, False, 0, 0, 0, 0, 0, 0
    if not t0 < t1:
        # At most a single point of the segment touches the box.
        if end_in:
            buf[0] = end_flat
            return 1, True, ex, ey, ez, ex, ey, ez
        return 0, False, 0, 0, 0, 0, 0, 0

    # First and last voxels; clamping absorbs rounding of points computed on the box faces.
    ix = _floor_in(ax + t0 * dx, nx)
    iy = _floor_in(ay + t0 * dy, ny)
    iz = _floor_in(az + t0 * dz, nz)
    if end_in:
        lx, ly, lz = ex, ey, ez
    else:
        lx = _floor_in(ax + t1 * dx, nx)
        ly = _floor_in(ay + t1 * dy, ny)
        lz = _floor_in(az + t1 * dz, nz)
    sx, tmx, tdx = _axis_start(ax, dx, ix)
    sy, tmy, tdy = _axis_start(ay, dy, iy)
    sz, tmz, tdz = _axis_start(az, dz, iz)
    # Face crossings left per axis. Counting them, rather than testing t against t1, keeps the
    # walk inside the grid and makes it end on the last voxel whatever the rounding.
    cx = (lx - ix) * sx
    cy = (ly - iy) * sy
    cz = (lz - iz) * sz
    if cx < 0 or cy < 0 or cz < 0:
        # Only when rounding puts the entry past the end (segment shorter than rounding).
        if end_in:
            buf[0] = end_flat
            return 1, True, ex, ey, ez, ex, ey, ez
        return 0, False, 0, 0, 0, 0, 0, 0
    if cx == 0:
        tmx = math.inf
    if cy == 0:
        tmy = math.inf
    if cz == 0:
        tmz = math.inf
    stx = sx * ny * nz
    sty = sy * nz
    idx = (ix * ny + iy) * nz + iz
    n = cx + cy + cz
    buf[0] = idx
    for s in range(1, n + 1):
        if tmx <= tmy and tmx <= tmz:
            idx += stx
            cx -= 1
            tmx = math.inf if cx == 0 else tmx + tdx
        elif tmy <= tmz:
            idx += sty
            cy -= 1
            tmy = math.inf if cy == 0 else tmy + tdy
        else:
            idx += sz
            cz -= 1
            tmz = math.inf if cz == 0 else tmz + tdz
        buf[s] = idx
    return n + 1, end_in, ix, iy, iz, lx, ly, lz


@numba.njit(cache=True, inline="always")
def _grow_box(box: IndexArray, i: int, j: int, k: int) -> None:
    """Grow the inclusive (6,) min i, j, k / max i, j, k box over voxel (i, j, k)."""
    box[0] = min(box[0], i)
    box[1] = min(box[1], j)
    box[2] = min(box[2], k)
    box[3] = max(box[3], i)
    box[4] = max(box[4], j)
    box[5] = max(box[5], k)


@numba.njit(cache=True, inline="always")
def _unflatten(v: int, ny: int, nz: int) -> tuple[int, int, int]:
    """(i, j, k) of the flat C-order index v in a (nx, ny, nz) grid."""
    q = v // nz
    i = q // ny
    return i, q - i * ny, v - q * nz


@numba.njit(cache=True)
def integrate_rays(
    origin: FloatArray, endpoints: FloatArray, hit: BoolArray,
    grid_origin: FloatArray, voxel_size: float,
    log_odds: LogOddsGrid, state: StateGrid,
    l_hit: float, l_miss: float, l_min: float, l_max: float, threshold: float,
    touched: IndexArray, changed: IndexArray,
    stamp: npt.NDArray[np.int64], batch: int,
) -> int:
    """Update the grid with a batch of rays sharing one origin (one depth frame).

    Each voxel is updated at most once per batch, and hits win (as OctoMap does): a voxel in
    which any ray ends on a surface gets `l_hit`; every other in-grid voxel that some ray passes
    through, or ends in without a return, gets `l_miss`. Without this, the many grazing rays of
    one frame that pass through a wall's surface voxel would outvote the rays that hit it and
    carve holes in walls. Log-odds are clamped to [l_min, l_max]. Rays with a non-finite
    endpoint are skipped; parts of rays outside the grid are skipped; the origin may lie outside.

    `stamp` (nx*ny*nz,) int64 holds, per voxel, the last batch tag that touched it; `batch` must
    grow from call to call (tags 3*batch: hit pending, 3*batch+1: miss applied, 3*batch+2: hit
    applied).

    Args:
        origin: (3,) float64 sensor position, world metres.
        endpoints: (N, 3) float64 ray ends, world metres.
        hit: (N,) bool, True where the ray ends on a surface.
        grid_origin: (3,) float64 lower corner of voxel (0, 0, 0).
        log_odds: (nx, ny, nz) float32 C-contiguous, updated in place.
        state: (nx, ny, nz) uint8 C-contiguous `VoxelState`, updated in place.
        touched: (6,) int64 min i, j, k then max i, j, k of all updated voxels, grown in place.
        changed: (6,) int64 the same for voxels whose state changed, grown in place.

    Returns:
        Number of voxels that went from UNKNOWN to known.
    """
    nx, ny, nz = log_odds.shape
    flat_l = log_odds.reshape(-1)
    flat_s = state.reshape(-1)
    buf = np.empty(nx + ny + nz + 3, dtype=np.int64)
    ax = (origin[0] - grid_origin[0]) / voxel_size
    ay = (origin[1] - grid_origin[1]) / voxel_size
    az = (origin[2] - grid_origin[2]) / voxel_size
    if not (math.isfinite(ax) and math.isfinite(ay) and math.isfinite(az)):
        return 0
    newly = 0
    hit_tag = 3 * batch
    miss_tag = 3 * batch + 1
    done_tag = 3 * batch + 2
    # First pass: the voxels where rays end on a surface, so that the second pass skips them.
    for r in range(endpoints.shape[0]):
        if not hit[r]:
            continue
        bx = (endpoints[r, 0] - grid_origin[0]) / voxel_size
        by = (endpoints[r, 1] - grid_origin[1]) / voxel_size
        bz = (endpoints[r, 2] - grid_origin[2]) / voxel_size
        if not (math.isfinite(bx) and math.isfinite(by) and math.isfinite(bz)):
            continue
        # The walk of a ray ending in the grid ends in floor(b) (see `_traverse`).
        ex = math.floor(bx)
        ey = math.floor(by)
        ez = math.floor(bz)
        if 0 <= ex < nx and 0 <= ey < ny and 0 <= ez < nz:
            stamp[(ex * ny + ey) * nz + ez] = hit_tag
    for r in range(endpoints.shape[0]):
        bx = (endpoints[r, 0] - grid_origin[0]) / voxel_size
        by = (endpoints[r, 1] - grid_origin[1]) / voxel_size
        bz = (endpoints[r, 2] - grid_origin[2]) / voxel_size
        if not (math.isfinite(bx) and math.isfinite(by) and math.isfinite(bz)):
            continue
        count, _, fi, fj, fk, li, lj, lk = _traverse(ax, ay, az, bx, by, bz, nx, ny, nz, buf)
        if count == 0:
            continue
        first_change = -1
        last_change = -1
        # Inline rather than a per-voxel function call: this loop is the hot path.
        for c in range(count):
            v = buf[c]
            tag = stamp[v]
            if tag in (miss_tag, done_tag):
                continue
            if tag == hit_tag:
                delta = l_hit
                stamp[v] = done_tag
            else:
                delta = l_miss
                stamp[v] = miss_tag
            new = np.float32(min(max(flat_l[v] + delta, l_min), l_max))
            flat_l[v] = new
            # The state follows the stored float32, so state == (log_odds > threshold).
            s_new = _OCCUPIED if new > threshold else _FREE
            s_old = flat_s[v]
            if s_new != s_old:
                flat_s[v] = s_new
                if s_old == _UNKNOWN:
                    newly += 1
                if first_change < 0:
                    first_change = c
                last_change = c
        # A DDA path is monotone on every axis, so the first and last of any of its voxels
        # bound all of them.
        _grow_box(touched, fi, fj, fk)
        _grow_box(touched, li, lj, lk)
        if first_change >= 0:
            i, j, k = _unflatten(buf[first_change], ny, nz)
            _grow_box(changed, i, j, k)
            i, j, k = _unflatten(buf[last_change], ny, nz)
            _grow_box(changed, i, j, k)
    return newly


@numba.njit(cache=True)
def _ray_voxels(a: FloatArray, b: FloatArray, nx: int, ny: int, nz: int) -> IndexArray:
    """(K, 3) int64 voxels segment a→b (grid units) visits in the grid, in order."""
    buf = np.empty(nx + ny + nz + 3, dtype=np.int64)
    count = _traverse(a[0], a[1], a[2], b[0], b[1], b[2], nx, ny, nz, buf)[0]
    out = np.empty((count, 3), dtype=np.int64)
    for c in range(count):
        out[c, 0], out[c, 1], out[c, 2] = _unflatten(buf[c], ny, nz)
    return out


def _empty_box() -> IndexArray:
    big = np.iinfo(np.int64).max
    return np.array([big, big, big, -1, -1, -1], dtype=np.int64)


def _to_index_box(box: IndexArray) -> IndexBox | None:
    """Inclusive (6,) min/max bounds to a half-open box; None when nothing was recorded."""
    if box[3] < 0:
        return None
    return IndexBox(
        (int(box[0]), int(box[1]), int(box[2])),
        (int(box[3]) + 1, int(box[4]) + 1, int(box[5]) + 1),
    )


class OccupancyMap:
    """Log-odds occupancy grid with a running count of known voxels.

    Args:
        origin: (3,) lower corner of voxel (0, 0, 0), world metres.
        shape: (nx, ny, nz) number of voxels per axis.
        voxel_size: voxel edge, metres.
        config: sensor model; `OccupancyConfig()` when None.
    """

    def __init__(
        self,
        origin: npt.ArrayLike,
        shape: tuple[int, int, int],
        voxel_size: float,
        config: OccupancyConfig | None = None,
    ) -> None:
        self._origin = np.array(origin, dtype=np.float64).reshape(3)
        self._origin.setflags(write=False)
        if len(shape) != 3 or min(shape) < 1:
            raise ValueError(f"shape must be three positive sizes, got {shape}")
        self._shape = (int(shape[0]), int(shape[1]), int(shape[2]))
        if not voxel_size > 0.0:
            raise ValueError("voxel_size must be positive")
        self._voxel_size = float(voxel_size)
        self.config = config or OccupancyConfig()
        self._log_odds = np.zeros(self._shape, dtype=np.float32)
        self._state = np.zeros(self._shape, dtype=np.uint8)
        self._known = 0
        self._stamp = np.full(self._log_odds.size, -1, dtype=np.int64)
        self._batch = 0
        self._last_touched: IndexBox | None = None
        self._subscriptions: weakref.WeakSet[DirtyBoxSubscription] = weakref.WeakSet()

    @property
    def origin(self) -> FloatArray:
        """(3,) lower corner of voxel (0, 0, 0), read-only."""
        return self._origin

    @property
    def shape(self) -> tuple[int, int, int]:
        return self._shape

    @property
    def voxel_size(self) -> float:
        return self._voxel_size

    @property
    def state(self) -> StateGrid:
        """(nx, ny, nz) uint8 `VoxelState` values, a read-only view."""
        view = self._state.view()
        view.setflags(write=False)
        return view

    @property
    def log_odds(self) -> LogOddsGrid:
        """(nx, ny, nz) float32 log-odds, a read-only view."""
        view = self._log_odds.view()
        view.setflags(write=False)
        return view

    @property
    def known_count(self) -> int:
        """Number of voxels that are not UNKNOWN."""
        return self._known

    @property
    def explored_volume_m3(self) -> float:
        """Known voxels times the voxel volume."""
        return self._known * self._voxel_size**3

    @property
    def last_touched_box(self) -> IndexBox | None:
        """Box of every voxel the last `integrate` updated (None if it updated none)."""
        return self._last_touched

    def copy_state(self) -> StateGrid:
        """(nx, ny, nz) uint8 writable copy of the states."""
        return self._state.copy()

    def subscribe(self) -> DirtyBoxSubscription:
        """A new box that accumulates the voxels whose state changes from now on.

        The map keeps only a weak reference: the subscription lives as long as its owner.
        """
        sub = DirtyBoxSubscription()
        self._subscriptions.add(sub)
        return sub

    def integrate(self, origin: npt.ArrayLike, endpoints: npt.ArrayLike,
                  hit: npt.ArrayLike) -> int:
        """Cast one batch of rays from a common origin into the map.

        Args:
            origin: (3,) sensor position, world metres (may be outside the grid).
            endpoints: (N, 3) ray ends, world metres.
            hit: (N,) bool, True where the ray ends on a surface; see
                `OccupancyConfig.clear_max_range` for rays without a return.

        Returns:
            Number of voxels that became known.
        """
        o = np.ascontiguousarray(origin, dtype=np.float64).reshape(3)
        ends = np.ascontiguousarray(endpoints, dtype=np.float64).reshape(-1, 3)
        hits = np.ascontiguousarray(hit, dtype=np.bool_).reshape(-1)
        if len(hits) != len(ends):
            raise ValueError(f"{len(ends)} endpoints but {len(hits)} hit flags")
        if not self.config.clear_max_range:
            ends, hits = np.ascontiguousarray(ends[hits]), hits[hits]
        cfg = self.config
        touched = _empty_box()
        changed = _empty_box()
        self._batch += 1
        newly = int(
            integrate_rays(
                o, ends, hits, np.ascontiguousarray(self._origin), self._voxel_size,
                self._log_odds, self._state,
                cfg.log_odds_hit, cfg.log_odds_miss, cfg.clamp_min, cfg.clamp_max,
                cfg.occupied_threshold, touched, changed, self._stamp, self._batch,
            )
        )
        self._known += newly
        self._last_touched = _to_index_box(touched)
        box = _to_index_box(changed)
        if box is not None:
            for sub in self._subscriptions:
                sub.merge(box)
        return newly

    def world_to_index(self, points: npt.ArrayLike) -> IndexArray:
        """(..., 3) world points to (..., 3) int64 indices of the voxels holding them.

        The result may lie outside the grid; see `in_bounds`.
        """
        p = np.asarray(points, dtype=np.float64)
        return np.floor((p - self._origin) / self._voxel_size).astype(np.int64)

    def index_to_world(self, idx: npt.ArrayLike) -> FloatArray:
        """(..., 3) voxel indices to (..., 3) float64 voxel centres, world metres."""
        i = np.asarray(idx, dtype=np.float64)
        return self._origin + (i + 0.5) * self._voxel_size

    def in_bounds(self, idx: npt.ArrayLike) -> BoolArray:
        """(...,) True where the (..., 3) index lies inside the grid."""
        i = np.asarray(idx)
        upper = np.array(self._shape)
        return np.all((i >= 0) & (i < upper), axis=-1)

    def ray_voxels(self, origin: npt.ArrayLike, endpoint: npt.ArrayLike) -> IndexArray:
        """(K, 3) int64 in-grid voxels the segment origin→endpoint visits, in order.

        The endpoint's voxel, when in the grid, comes last; these are exactly the voxels one ray
        of `integrate` updates.
        """
        a = (np.asarray(origin, dtype=np.float64).reshape(3) - self._origin) / self._voxel_size
        b = (np.asarray(endpoint, dtype=np.float64).reshape(3) - self._origin) / self._voxel_size
        if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
            return np.zeros((0, 3), dtype=np.int64)
        nx, ny, nz = self._shape
        result: IndexArray = _ray_voxels(a, b, nx, ny, nz)
        return result
