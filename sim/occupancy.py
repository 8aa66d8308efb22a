"""Probabilistic occupancy grid updated by casting depth rays through it.

The grid convention (which voxel a point belongs to) is `sim.voxel_grid`'s; the ray casting is
in `sim.occupancy_kernels`.

Each voxel keeps a float32 log-odds value and a uint8 `VoxelState`. A voxel is UNKNOWN until a
ray first touches it; from then on it is OCCUPIED when its log-odds exceed the threshold and FREE
otherwise.

The update is OctoMap's (Hornung et al., Autonomous Robots 34(3), 2013; `OccupancyConfig`):
clamped log-odds, a hit for the voxel a ray returns in, a miss for every other voxel it passes
through; within one depth frame each voxel is updated once, and a voxel some ray returned in
takes the hit whatever other rays passed through it (OctoMap's scan update prefers occupied
cells over free ones). Two rules are added, for surfaces thinner than a voxel:

**A return is believed until a ray contradicts it.** Every voxel also keeps where in it rays
have returned: the running mean of one return point per frame (the first ray's of the frame to
return there), to 1/256 of the voxel per axis, over the last 16 or so frames, and how many
returns that mean holds. A hit leaves the voxel OCCUPIED, with log-odds at least
`occupied_threshold + log_odds_hit` (a lone hit's), however many misses of earlier rays had
brought it lower. A miss is then counted only from a ray that says something about the returns:

- returns from two or more frames (a surface seen): a ray passing within
  `OccupancyConfig.miss_radius_m` of their mean and running on past it by more than the radius
  plus twice the range noise at the ray's length (`OccupancyConfig.range_noise`); rays that
  pass elsewhere through the voxel, or return within that margin of the mean, leave it alone;
- returns from one frame: a ray passing within the radius of the return, or one returning on a
  surface near it along the ray (ending less than a voxel's diagonal plus that margin past the
  ray's nearest point to it), of which the return may be range noise; rays passing beside it
  and running on leave it alone;
- no returns: every ray through it, as in OctoMap.

A miss that drives the voxel down to `clamp_min` forgets its returns. Why:

- Thin surfaces. A rail, wire, rod or plate edge fills a few centimetres of a 10-20 cm voxel. In
  OctoMap's model every ray through the rest of the voxel is a miss: seen from 4-5 m, where rays
  are about 10 cm apart and more of them pass a 5 cm rail's voxel than hit it, the voxel loses
  more than it gains and is cleared within about nine frames (`docs/notes/2026-11-safety-stops.md`).
  A ray passing beside the rail says nothing about the rail. Nor do the misses dealt before the
  first hit: rays passing a 2 cm rod in a 0.2 m voxel free the voxel before one hits the rod,
  and summed with them the hit left it FREE; planners flew into such rods on WAREHOUSE once the
  camera no longer faced them (`docs/notes/2026-12-warehouse-rod.md`). The radius, 1 cm, is half
  the width of the thinnest parts the areas hold (the 2 cm flanges of steel columns, lamp rods,
  2.4 cm handles): a ray that close to a point on the middle of such a part hits it.
- Range noise. Depth noise puts a thin surface's own returns up to a few centimetres behind it
  (sigma 4 cm at 5 m, `sim.noise`), often in the next voxel; their rays pass the surface's
  returns and must not count against them.
- Speckle. Range noise also puts a wall's returns in the voxel in front of it. Such a return
  lies within the noise of the wall behind it, so the rays of the next frames that return on
  the wall through that voxel clear it, as in OctoMap. Returns that collected in two or more
  frames are cleared only by rays through their mean: within a few frames when seen from a
  metre or two, slowly when seen only from 4-5 m, where rays are 8-10 cm apart and a wall's
  range noise is 3-4 cm (`docs/notes/2026-12-map-fidelity.md` and
  `docs/notes/2026-12-warehouse-rod.md` have the measurements).

The rule is a hard-threshold form of the miss update of NDT occupancy maps (Saarinen et al.,
IJRR 32(14), 2013), which weighs the miss of a ray through a cell by how likely the ray passes
through the Gaussian of the points seen in the cell, reduced here to the points' mean and a
radius; voxblox (Oleynikova et al., IROS 2017) answers the same fading of thin and sparse
surfaces by the free-space parts of rays passing through their voxels with a larger weight for
near-surface observations (its `sparsity_compensation_factor`).

Consumers that derive data from the states (frontiers, clearance) follow changes through
`DirtyBoxSubscription`: every subscription accumulates the bounding box of the voxels whose
state changed since its own last `take()`, so several consumers can be refreshed from the same
integrations at their own pace without sharing or resetting each other's box.
"""

from __future__ import annotations

import weakref

import numpy as np
import numpy.typing as npt
from pydantic import BaseModel, ConfigDict, Field, model_validator

from sim.geometry import FloatArray
from sim.noise import DepthNoiseConfig
from sim.occupancy_kernels import FRESH_TAG, _ray_voxels, decode_returns, integrate_rays
from sim.voxel_grid import (
    BoolArray,
    DirtyBoxSubscription,
    IndexArray,
    IndexBox,
    LogOddsGrid,
    StateGrid,
    VoxelState,
)

__all__ = [
    "DirtyBoxSubscription",
    "IndexArray",
    "IndexBox",
    "OccupancyConfig",
    "OccupancyMap",
    "StateGrid",
    "VoxelState",
]


class OccupancyConfig(BaseModel):
    """Log-odds sensor model (see the module docstring for the surface-evidence rule).

    Attributes:
        log_odds_hit: added to the voxel holding a ray's return (which is then at least at
            `occupied_threshold + log_odds_hit`).
        log_odds_miss: added to every voxel a ray passes through before its end (a voxel holding
            returns: only by rays that contradict them, see the module docstring).
        clamp_min: lower bound of the log-odds, so free space can turn occupied again quickly.
        clamp_max: upper bound of the log-odds.
        occupied_threshold: a known voxel is OCCUPIED when its log-odds is > this, else FREE.
        clear_max_range: rays without a return (hit False) carve free space up to their end,
            end voxel included; when False such rays are ignored.
        miss_radius_m: a voxel holding returns takes a miss from a ray passing within this
            distance of their mean (from one frame: also from a ray returning just behind it).
        range_noise: the range noise the map allows for beyond a voxel's returns (twice its
            sigma at the ray's length); the benchmark camera's by default. Disabled: none.
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    log_odds_hit: float = Field(0.85, gt=0.0)
    log_odds_miss: float = Field(-0.4, lt=0.0)
    clamp_min: float = -2.0
    clamp_max: float = 3.5
    occupied_threshold: float = 0.0
    clear_max_range: bool = True
    miss_radius_m: float = Field(0.01, gt=0.0)
    range_noise: DepthNoiseConfig = DepthNoiseConfig()

    @model_validator(mode="after")
    def _ordered_bounds(self) -> OccupancyConfig:
        if not self.clamp_min <= self.occupied_threshold < self.clamp_max:
            raise ValueError("need clamp_min <= occupied_threshold < clamp_max")
        return self


# Frames with returns a voxel needs before rays passing beside them stop counting as misses.
MIN_RETURNS = 2
# The mean of a voxel's returns averages about this many of the latest ones.
_WINDOW = 16
# Returns within this many sigmas of range noise beyond a voxel's returns agree with them.
_NOISE_SIGMAS = 2.0


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
        # Per voxel the last batch that touched it and where rays returned in it (the layout
        # is `sim.occupancy_kernels`').
        self._voxels = np.zeros((self._log_odds.size, 2), dtype=np.uint32)
        self._voxels[:, 0] = FRESH_TAG
        # One bit per voxel (flat index v: byte v >> 3, bit v & 7), set where the returns word
        # is `SETTLED`: most voxels a ray crosses are, and the bits of a region fit in the cache
        # where their words do not.
        self._settled = np.zeros((self._log_odds.size + 7) // 8, dtype=np.uint8)
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
        """Box of every voxel the rays of the last `integrate` visited, so of every voxel it
        updated (None if they visited none)."""
        return self._last_touched

    def returns(self, idx: npt.ArrayLike) -> tuple[FloatArray, npt.NDArray[np.int64]]:
        """Where rays have returned in the in-grid voxels `idx` (K, 3): the mean return point
        (K, 3), world metres (to 1/256 of the voxel; NaN where the voxel holds none), and how
        many returns, one per frame, that mean holds (K,), saturating at its window (16)."""
        i = np.asarray(idx, dtype=np.int64).reshape(-1, 3)
        flat = np.ravel_multi_index(tuple(i.T), self._shape)
        inside, count = decode_returns(self._voxels[flat, 1])
        points = self._origin + (i + inside) * self._voxel_size
        points[count == 0] = np.nan
        return points, count

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
        noise = cfg.range_noise
        touched = _empty_box()
        changed = _empty_box()
        self._batch += 1
        if self._batch >= 1 << 30:
            raise RuntimeError("more than 2^30 integrations into one occupancy map")
        newly = int(
            integrate_rays(
                o, ends, hits, np.ascontiguousarray(self._origin), self._voxel_size,
                self._log_odds, self._state,
                cfg.log_odds_hit, cfg.log_odds_miss, cfg.clamp_min, cfg.clamp_max,
                cfg.occupied_threshold, cfg.miss_radius_m / self._voxel_size,
                _NOISE_SIGMAS if noise.enabled else 0.0, noise.sigma_a, noise.sigma_b, noise.z0,
                MIN_RETURNS, _WINDOW, touched, changed, self._voxels, self._settled,
                self._batch,
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
