"""Fusing one depth frame into the TSDF's voxel blocks in one compiled pass: the values of
Open3D's `VoxelBlockGrid.integrate`, to the bit.

Open3D (v0.19-v0.20 CPU kernel, `IntegrateCPU`) visits every voxel of the frame's blocks in a
generic parallel loop and spends about 20 ns on each (one thread); the same arithmetic over a
block's voxels in order, with each axis's products made once per block, takes about a third of
that. The rules kept from Open3D's kernel, all in float32:

- the voxel (x, y, z) (integer voxel coordinates) is at `float(x) * voxel_size` ...; in the
  camera frame `xc = ((x*e00 + y*e01) + z*e02) + e03` (the extrinsic's rows rounded to float32);
- it projects to `u = (fx * xc) * (1 / zc) + cx` (and v alike), kept when `0 <= u <= W - 1` and
  `0 <= v <= H - 1`, reading the depth at the truncated (int(v), int(u));
- it is left alone when that depth is not in (0, depth_max], or `zc <= 0`, or it lies more
  than the truncation behind the depth; otherwise `sdf = min(depth - zc, trunc) / trunc`,
  `tsdf = (w * tsdf + sdf) * (1 / (w + 1))`, `w = w + 1`.

Each voxel's update reads only its own values, so the order of the blocks changes nothing.
`open3d_fuse` is Open3D's own call, kept as the reference the tests and benchmarks compare with.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numba
import numpy as np
import numpy.typing as npt

from sim.open3d_any import o3c, o3d


@dataclass(frozen=True)
class FusionParameters:
    """A camera's and a grid's constants as Open3D's kernel holds them (float32).

    Attributes:
        intrinsic: (4,) fx, fy, cx, cy in pixels.
        voxel_size: metres.
        trunc: the truncation in metres, `voxel_size * trunc_multiplier` rounded as Open3D does.
        depth_max: metres; a depth above it is no return.
    """

    intrinsic: npt.NDArray[np.float32]
    voxel_size: np.float32
    trunc: np.float32
    depth_max: np.float32

    @classmethod
    def of(cls, intrinsic: npt.ArrayLike, voxel_size: float, trunc_multiplier: float,
           depth_max: float) -> FusionParameters:
        """From a (3, 3) pinhole matrix and the grid's settings."""
        k = np.asarray(intrinsic, dtype=np.float64)
        size = np.float32(voxel_size)
        return cls(np.array([k[0, 0], k[1, 1], k[0, 2], k[1, 2]], dtype=np.float32), size,
                   np.float32(size * np.float32(trunc_multiplier)), np.float32(depth_max))


def fuse_depth(grid: Any, block_coords: Any, depth: npt.NDArray[np.float32],
               extrinsic: npt.NDArray[np.float64], params: FusionParameters) -> None:
    """Fuse `depth` into `grid` (a CPU `VoxelBlockGrid` with float32 "tsdf" and "weight") over
    the blocks `block_coords` ((N, 3) int32 Open3D tensor, as `compute_unique_block_coordinates`
    gives), allocating those not yet allocated.

    Args:
        depth: (H, W) float32 z-depth in metres, 0 where there is no return (no NaN).
        extrinsic: (4, 4) optical-from-world transform.
    """
    table = grid.hashmap()
    table.activate(block_coords)  # may grow the table: its arrays are read after this
    slots, _ = table.find(block_coords)
    tsdf = grid.attribute("tsdf").numpy()  # (capacity, R, R, R, 1), without a copy
    shape = tsdf.shape[:4]
    _fuse(slots.numpy().astype(np.int64), table.key_tensor().numpy(), tsdf.reshape(shape),
          grid.attribute("weight").numpy().reshape(shape), np.ascontiguousarray(depth),
          np.ascontiguousarray(extrinsic[:3], dtype=np.float32), params.intrinsic,
          params.voxel_size, params.trunc, params.depth_max)


def open3d_fuse(grid: Any, block_coords: Any, depth: npt.NDArray[np.float32],
                intrinsic: npt.ArrayLike, extrinsic: npt.NDArray[np.float64],
                trunc_multiplier: float, depth_max: float) -> None:
    """The same fusion by Open3D's `VoxelBlockGrid.integrate` (the reference)."""
    image = o3d.t.geometry.Image(o3c.Tensor(np.ascontiguousarray(depth, dtype=np.float32)))
    grid.integrate(block_coords, image, o3c.Tensor(np.asarray(intrinsic, dtype=np.float64)),
                   o3c.Tensor(np.asarray(extrinsic, dtype=np.float64)), 1.0, depth_max,
                   trunc_multiplier)


@numba.njit(cache=True, error_model="numpy")
def _fuse(slots: npt.NDArray[np.int64], keys: npt.NDArray[np.int32],
          tsdf: npt.NDArray[np.float32], weight: npt.NDArray[np.float32],
          depth: npt.NDArray[np.float32], ext: npt.NDArray[np.float32],
          intrinsic: npt.NDArray[np.float32], voxel_size: np.float32, trunc: np.float32,
          depth_max: np.float32) -> None:  # pragma: no cover - numba
    """The update of the module's docstring over the blocks in `slots`; tsdf and weight
    (capacity, R, R, R) indexed [slot, z, y, x]. Every operation is float32 and in Open3D's
    order; the per-axis products (`px` ...) are the same products it makes per voxel."""
    res = tsdf.shape[1]
    height, width = depth.shape
    u_max = np.float32(width - 1)
    v_max = np.float32(height - 1)
    zero = np.float32(0.0)
    one = np.float32(1.0)
    fx, fy, cx, cy = intrinsic[0], intrinsic[1], intrinsic[2], intrinsic[3]
    below = -trunc
    px = np.empty((res, 3), dtype=np.float32)
    py = np.empty((res, 3), dtype=np.float32)
    pz = np.empty((res, 3), dtype=np.float32)
    for b in range(slots.shape[0]):
        s = slots[b]
        x0 = np.int64(keys[s, 0]) * res
        y0 = np.int64(keys[s, 1]) * res
        z0 = np.int64(keys[s, 2]) * res
        for i in range(res):
            xi = np.float32(x0 + i) * voxel_size
            yi = np.float32(y0 + i) * voxel_size
            zi = np.float32(z0 + i) * voxel_size
            for r in range(3):
                px[i, r] = xi * ext[r, 0]
                py[i, r] = yi * ext[r, 1]
                pz[i, r] = zi * ext[r, 2]
        block_tsdf = tsdf[s]
        block_weight = weight[s]
        for k in range(res):
            for j in range(res):
                for i in range(res):
                    zc = px[i, 2] + py[j, 2] + pz[k, 2] + ext[2, 3]
                    if not zc > zero:  # behind the camera: Open3D drops it after projecting
                        continue
                    xc = px[i, 0] + py[j, 0] + pz[k, 0] + ext[0, 3]
                    yc = px[i, 1] + py[j, 1] + pz[k, 1] + ext[1, 3]
                    inv_z = one / zc
                    u = fx * xc * inv_z + cx
                    v = fy * yc * inv_z + cy
                    if not (v >= zero and u >= zero and v <= v_max and u <= u_max):
                        continue
                    d = depth[np.int64(v), np.int64(u)]
                    sdf = d - zc
                    if d <= zero or d > depth_max or sdf < below:
                        continue
                    if not sdf < trunc:
                        sdf = trunc
                    sdf = sdf / trunc
                    w = block_weight[k, j, i]
                    inv_sum = one / (w + one)
                    block_tsdf[k, j, i] = (w * block_tsdf[k, j, i] + sdf) * inv_sum
                    block_weight[k, j, i] = w + one
