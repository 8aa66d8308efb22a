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

The blocks a frame touches are Open3D's `compute_unique_block_coordinates` (`DepthTouchCPU`,
v0.19-v0.20), compiled as `touched_blocks`: every fourth row and column of the image, a pixel
kept when its depth d is in (0, depth_max) (open at both ends here), the camera pose the
extrinsic's inverse in float64 (`R'` = `R.T`, `t' = -(R' t)` summed in order) rounded to
float32, the pixel's ray `(u - cx) * 1 / fx` (v alike) at unit depth taken to the world as
`((x*p00 + y*p01) + 1*p02) + p03` less the camera position, and four samples along it from
`max(d - trunc, 0)` to `min(d + trunc, depth_max)` in steps of a third of that span, each in
the block `floor((o + t * dir) / block_size)`; all float32. A set: Open3D lists it in its hash
set's order, `touched_blocks` in the order the samples first meet each block.
"""

from __future__ import annotations

import math
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


def touched_blocks(depth: npt.NDArray[np.float32], extrinsic: npt.NDArray[np.float64],
                   params: FusionParameters, resolution: int) -> npt.NDArray[np.int32]:
    """(N, 3) int32 keys of the blocks of `resolution`³ voxels the frame touches, each once, in
    the order the image's samples meet them: the set Open3D's
    `compute_unique_block_coordinates` gives (module docstring).

    Args:
        depth: (H, W) float32 z-depth in metres, 0 where there is no return (no NaN).
        extrinsic: (4, 4) float64 optical-from-world transform.
    """
    block_size = np.float32(params.voxel_size * np.float32(resolution))
    return _touched_blocks(np.ascontiguousarray(depth), np.ascontiguousarray(extrinsic,
                           dtype=np.float64), params.intrinsic, block_size, params.trunc,
                           params.depth_max, _DEPTH_STRIDE)


def open3d_blocks(grid: Any, depth: npt.NDArray[np.float32], intrinsic: npt.ArrayLike,
                  extrinsic: npt.NDArray[np.float64], trunc_multiplier: float,
                  depth_max: float) -> npt.NDArray[np.int32]:
    """The same blocks by Open3D's `compute_unique_block_coordinates` (the reference), as
    (N, 3) int32 in Open3D's order; (0, 3) where Open3D finds none."""
    image = o3d.t.geometry.Image(o3c.Tensor(np.ascontiguousarray(depth, dtype=np.float32)))
    try:
        blocks = grid.compute_unique_block_coordinates(
            image, o3c.Tensor(np.asarray(intrinsic, dtype=np.float64)),
            o3c.Tensor(np.asarray(extrinsic, dtype=np.float64)), 1.0, depth_max,
            trunc_multiplier)
    except RuntimeError as exc:
        if "block" not in str(exc).lower():
            raise
        return np.zeros((0, 3), dtype=np.int32)
    keys: npt.NDArray[np.int32] = blocks.numpy()
    return keys


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


# Open3D samples every fourth row and column of the image for the blocks it touches
# (`VoxelBlockGrid::GetUniqueBlockCoordinates`, `down_factor`).
_DEPTH_STRIDE = 4
# Samples per pixel less one (`DepthTouchCPU`'s `step_size`).
_STEPS = 3
# A block key's axes packed in one int64: 21 bits each, offset by half their range, so a key
# must lie within 2^20 blocks of the origin on each axis (420 km at the default 0.4 m blocks).
_KEY_BITS = 21
_KEY_HALF = 1 << (_KEY_BITS - 1)
# Fibonacci hashing's multiplier, 2^64 / the golden ratio: the set's slot is the product's top
# bits.
_GOLDEN = 0x9E3779B97F4A7C15


@numba.njit(cache=True, error_model="numpy")
def _touched_blocks(depth: npt.NDArray[np.float32], extrinsic: npt.NDArray[np.float64],
                    intrinsic: npt.NDArray[np.float32], block_size: np.float32,
                    trunc: np.float32, depth_max: np.float32,
                    stride: int) -> npt.NDArray[np.int32]:  # pragma: no cover - numba
    """`touched_blocks`' keys in the order first met; every operation in Open3D's precision and
    order."""
    # The pose, Open3D's `InverseTransformation` in float64, then rounded as its indexer keeps it.
    pose = np.empty((3, 4), dtype=np.float32)
    for r in range(3):
        pose[r, 0] = np.float32(extrinsic[0, r])
        pose[r, 1] = np.float32(extrinsic[1, r])
        pose[r, 2] = np.float32(extrinsic[2, r])
        pose[r, 3] = np.float32(-(extrinsic[0, r] * extrinsic[0, 3]
                                  + extrinsic[1, r] * extrinsic[1, 3]
                                  + extrinsic[2, r] * extrinsic[2, 3]))
    fx, fy, cx, cy = intrinsic[0], intrinsic[1], intrinsic[2], intrinsic[3]
    one = np.float32(1.0)
    zero = np.float32(0.0)
    third = np.float32(_STEPS)
    ox, oy, oz = pose[0, 3], pose[1, 3], pose[2, 3]
    rows = depth.shape[0] // stride
    cols = depth.shape[1] // stride
    packed = np.empty(rows * cols * (_STEPS + 1), dtype=np.int64)
    m = 0
    for row in range(rows):
        y = row * stride
        for col in range(cols):
            x = col * stride
            d = depth[y, x]
            if not (d > zero and d < depth_max):
                continue
            xc = (np.float32(x) - cx) * one / fx
            yc = (np.float32(y) - cy) * one / fy
            # The point at unit depth in the world, then the ray from the camera through it.
            gx = xc * pose[0, 0] + yc * pose[0, 1] + one * pose[0, 2] + ox
            gy = xc * pose[1, 0] + yc * pose[1, 1] + one * pose[1, 2] + oy
            gz = xc * pose[2, 0] + yc * pose[2, 1] + one * pose[2, 2] + oz
            dx = gx - ox
            dy = gy - oy
            dz = gz - oz
            t_min = max(d - trunc, zero)
            t_max = min(d + trunc, depth_max)
            t_step = (t_max - t_min) / third
            t = t_min
            for _ in range(_STEPS + 1):
                bx = np.int64(math.floor((ox + t * dx) / block_size))
                by = np.int64(math.floor((oy + t * dy) / block_size))
                bz = np.int64(math.floor((oz + t * dz) / block_size))
                packed[m] = (((bx + _KEY_HALF) << (2 * _KEY_BITS))
                             | ((by + _KEY_HALF) << _KEY_BITS) | (bz + _KEY_HALF))
                m += 1
                t += t_step
    # Each key once, in the order first met: an open-addressing set over the packed keys.
    bits = 1
    while (1 << bits) < 2 * m:
        bits += 1
    table = np.full(1 << bits, -1, dtype=np.int64)
    out = np.empty((m, 3), dtype=np.int32)
    n = 0
    mask = (1 << _KEY_BITS) - 1
    for e in range(m):
        key = packed[e]
        if e > 0 and key == packed[e - 1]:
            continue  # the same block as the previous sample (most are)
        h = np.int64((np.uint64(key) * np.uint64(_GOLDEN)) >> np.uint64(64 - bits))
        while table[h] != -1 and table[h] != key:
            h = (h + 1) & ((1 << bits) - 1)
        if table[h] == key:
            continue
        table[h] = key
        out[n, 0] = np.int32(((key >> (2 * _KEY_BITS)) & mask) - _KEY_HALF)
        out[n, 1] = np.int32(((key >> _KEY_BITS) & mask) - _KEY_HALF)
        out[n, 2] = np.int32((key & mask) - _KEY_HALF)
        n += 1
    return out[:n]
