"""Truncated signed distance fusion of depth frames (Open3D VoxelBlockGrid on the CPU)."""

from __future__ import annotations

import math
from typing import Any

import numba
import numpy as np
import numpy.typing as npt
from pydantic import BaseModel, ConfigDict, Field

from sim.camera import BODY_FROM_OPTICAL
from sim.geometry import FloatArray, Pose, yaw_matrix
from sim.open3d_any import o3c
from sim.tsdf_blocks import block_grid
from sim.tsdf_fusion import FusionParameters, fuse_depth, touched_blocks
from sim.tsdf_mesh import MAX_RESOLUTION, marching_cubes
from sim.tsdf_points import crossing_points
from sim.tsdf_sampling import trilinear

# Open3D doubles a full block table, and a table's blocks are resident whether used or not
# (4 KiB each, zeroed): a FACILITY C run that needed 42,800 blocks held 80,000, and for the
# doubling the old table and the new one at once. The table grows by this factor instead.
BLOCK_GROWTH = 1.25
# The table made at the start holds the blocks the area's surface is expected to need
# (`surface_block_count`) times this, so that a run seldom grows it: each growth holds both
# tables at once (+229 MiB on FACILITY C, the highest point of the runs that grew) and costs
# about a second. A run fuses more blocks than the surface's own as odometry drift (up to
# 5 cm and 0.02 rad) and depth noise move its returns about: whole FACILITY C runs of 1,650 s
# ended with 1.14-1.19 times the count and passed 1.09 at 41-84 % of the flight
# (`docs/notes/2026-12-run-memory.md`). The margin also leaves room for a frame's blocks,
# which `_make_room` counts whole.
EXPECTED_BLOCK_MARGIN = 1.4


class TsdfConfig(BaseModel):
    """TSDF voxel size and truncation (truncation = voxel_size * trunc_voxel_multiplier)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    voxel_size_m: float = Field(0.05, gt=0.0)
    trunc_voxel_multiplier: float = Field(3.0, gt=0.0)
    # At most `sim.tsdf_mesh.MAX_RESOLUTION`: the marching cubes ranks a block's vertices in 13
    # bits.
    block_resolution: int = Field(8, ge=2, le=MAX_RESOLUTION)
    initial_block_count: int = Field(20000, ge=100)
    weight_threshold: float = Field(1.0, ge=0.0, description="min weight for extracted surface")


def surface_block_count(points: npt.ArrayLike, config: TsdfConfig) -> int:
    """How many voxel blocks lie within the truncation distance of `points` ((N, 3) metres,
    dense samples of a surface): about how many a TSDF fusing views of that surface allocates
    (Open3D allocates the blocks within the truncation of each depth return). Each point
    counts the blocks of the corners of the cube of half-width the truncation around it."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(pts) == 0:
        return 0
    block = config.voxel_size_m * config.block_resolution
    trunc = config.voxel_size_m * config.trunc_voxel_multiplier
    lo = np.floor((pts.min(axis=0) - trunc) / block).astype(np.int64)
    span = tuple(np.floor((pts.max(axis=0) + trunc) / block).astype(np.int64) - lo + 1)
    keys = [np.ravel_multi_index(tuple((np.floor((pts + corner) / block).astype(np.int64) - lo).T),
                                 span)
            for corner in np.array(np.meshgrid(*[(-trunc, trunc)] * 3)).reshape(3, -1).T]
    return len(np.unique(np.concatenate(keys)))


class TsdfVolume:
    """Fuses depth frames; extracts point clouds and meshes of the zero level set."""

    def __init__(self, intrinsic: FloatArray, max_range_m: float, config: TsdfConfig,
                 expected_blocks: int = 0) -> None:
        """`expected_blocks`: how many blocks the run is expected to fuse (0: unknown); the
        table starts with room for them. Which slot holds a block changes nothing a run
        computes (see `_make_room`)."""
        self.config = config
        self._fusion = FusionParameters.of(intrinsic, config.voxel_size_m,
                                           config.trunc_voxel_multiplier, max_range_m)
        self._grid = block_grid(
            config.voxel_size_m, config.block_resolution,
            max(config.initial_block_count, math.ceil(expected_blocks * EXPECTED_BLOCK_MARGIN)),
        )
        self.frames = 0

    @property
    def grid(self) -> Any:
        """The Open3D `VoxelBlockGrid` itself, for reading (fusing goes through `integrate`)."""
        return self._grid

    @staticmethod
    def extrinsic(pose: Pose) -> FloatArray:
        """(4, 4) optical-from-world transform of a camera at `pose`."""
        rot = yaw_matrix(pose.yaw) @ BODY_FROM_OPTICAL  # world from optical
        ext = np.eye(4)
        ext[:3, :3] = rot.T
        ext[:3, 3] = -rot.T @ pose.position
        return ext

    def integrate(self, depth: npt.NDArray[np.float32], pose: Pose) -> None:
        """Fuse one float32 z-depth image (NaN = no return) seen from `pose`."""
        clean, within = _without_nan(np.ascontiguousarray(depth, dtype=np.float32).reshape(-1),
                                     self._fusion.depth_max)
        if not within:
            return  # nothing within range: no block is touched
        clean = clean.reshape(depth.shape)
        extrinsic = self.extrinsic(pose)
        # Open3D's block coordinates and `integrate` values to the bit, compiled
        # (`sim.tsdf_fusion`).
        blocks = touched_blocks(clean, extrinsic, self._fusion, self.config.block_resolution)
        if len(blocks) == 0:
            return  # a frame whose returns touch no voxel block: nothing to fuse
        self._make_room(len(blocks))
        fuse_depth(self._grid, o3c.Tensor(blocks), clean, extrinsic, self._fusion)
        self.frames += 1

    def _make_room(self, touched: int) -> None:
        """Grow the block table, before Open3D would double it, so that `touched` more blocks
        fit: to `BLOCK_GROWTH` times its capacity, or more if they need it. Which slot holds
        a block changes nothing a run computes from the TSDF (every read goes by block key)."""
        table = self._grid.hashmap()
        needed = table.size() + touched
        capacity = table.capacity()
        if needed > capacity:
            table.reserve(max(needed, math.ceil(capacity * BLOCK_GROWTH)))

    def surface_points(self) -> npt.NDArray[np.float32]:
        """(N, 3) points on the fused surface, Open3D's `extract_point_cloud` points (float32;
        `sim.tsdf_points`), blocks in key order; empty before the first frame."""
        if self.frames == 0:
            return np.zeros((0, 3), dtype=np.float32)
        return crossing_points(self._grid, self.config.voxel_size_m, self.config.weight_threshold)

    def mesh(self) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int32]]:
        """Marching-cubes mesh of the fused surface: (V, 3) vertices and (F, 3) triangles."""
        if self.frames == 0:
            return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int32)
        return marching_cubes(self._grid, self.config.voxel_size_m, self.config.weight_threshold)

    def sdf_at(self, points: npt.NDArray[np.floating]) -> tuple[
        npt.NDArray[np.float64], npt.NDArray[np.float32]
    ]:
        """Signed distance (metres) at each point, trilinear between the 8 voxel samples around
        it, and the smallest fusion weight among those samples.

        Args:
            points: (N, 3) world points.

        Returns:
            sdf: (N,) metres, NaN where a sample is not allocated; weight: (N,) 0 there.
        """
        cfg = self.config
        if self.frames == 0:
            return np.full(len(points), np.nan), np.zeros(len(points), dtype=np.float32)
        sdf, weight = trilinear(self._grid, points, cfg.voxel_size_m)
        return sdf * cfg.voxel_size_m * cfg.trunc_voxel_multiplier, weight


_FLOAT32_MAX = np.finfo(np.float32).max


@numba.njit(cache=True)
def _without_nan(depth: npt.NDArray[np.float32], max_range: np.float32) -> tuple[
        npt.NDArray[np.float32], bool]:  # pragma: no cover - numba
    """(N,) `np.nan_to_num(depth, nan=0.0)` (infinities to float32's extremes) and whether any
    of its values lies in (0, max_range], compared in float32 as NumPy compares a float32
    image with a Python float: one pass where NumPy made four."""
    out = np.empty_like(depth)
    zero = np.float32(0.0)
    within = False
    for i in range(depth.shape[0]):
        d = depth[i]
        if math.isnan(d):
            d = zero
        elif math.isinf(d):
            d = _FLOAT32_MAX if d > zero else -_FLOAT32_MAX
        out[i] = d
        within |= zero < d <= max_range
    return out, within
