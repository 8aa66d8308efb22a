"""The fused surface as points: where the signed distance changes sign between two neighbouring
voxel samples, interpolated linearly along that axis. The points of Open3D's
`VoxelBlockGrid.extract_point_cloud`, computed in one compiled pass without its normals and
colours (`benchmarks/bookkeeping_ops.py` times the two), in an order fixed by the blocks' keys
rather than by Open3D's threads."""

from __future__ import annotations

from typing import Any

import numba
import numpy as np
import numpy.typing as npt

from sim.tsdf_blocks import block_arrays, slot_of


def crossing_points(grid: Any, voxel_size: float,
                    weight_threshold: float) -> npt.NDArray[np.float32]:
    """(N, 3) float32 metres: every sign change of the TSDF between voxels whose weights both
    exceed `weight_threshold`, along +x, +y and +z, blocks in key order.

    Args:
        grid: an Open3D CPU `VoxelBlockGrid` with float32 "tsdf" and "weight" attributes.
        voxel_size: its voxel edge, metres.
    """
    blocks = block_arrays(grid)
    if blocks is None:
        return np.zeros((0, 3), dtype=np.float32)
    after = _next_blocks(blocks.keys, blocks.order, blocks.sorted_keys, blocks.origin,
                         blocks.span)
    args = (blocks.keys, blocks.order, after, blocks.tsdf, blocks.weight,
            np.float32(weight_threshold), np.float32(voxel_size))
    count = _crossings(*args, np.zeros((0, 3), dtype=np.float32))
    points = np.empty((count, 3), dtype=np.float32)
    _crossings(*args, points)
    return points


@numba.njit(cache=True)
def _next_blocks(keys: npt.NDArray[np.int32], order: npt.NDArray[np.int64],
                 sorted_keys: npt.NDArray[np.int64], origin: npt.NDArray[np.int64],
                 span: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:  # pragma: no cover
    """For each block in `order`, the slot of the block after it along x, y and z (-1: none),
    (B, 3)."""
    after = np.full((order.shape[0], 3), -1, np.int64)
    for p in range(order.shape[0]):
        slot = order[p]
        bx, by, bz = keys[slot, 0], keys[slot, 1], keys[slot, 2]
        after[p, 0] = slot_of(sorted_keys, order, origin, span, bx + 1, by, bz)
        after[p, 1] = slot_of(sorted_keys, order, origin, span, bx, by + 1, bz)
        after[p, 2] = slot_of(sorted_keys, order, origin, span, bx, by, bz + 1)
    return after


@numba.njit(cache=True)
def _crossings(keys: npt.NDArray[np.int32], order: npt.NDArray[np.int64],
               after: npt.NDArray[np.int64], tsdf: npt.NDArray[np.float32],
               weight: npt.NDArray[np.float32], limit: np.float32, voxel: np.float32,
               out: npt.NDArray[np.float32]) -> int:  # pragma: no cover - numba
    """Counts the crossings; also writes them to `out` when it has rows (a second pass, with
    the count of the first). Arithmetic in float32, as Open3D's."""
    res = tsdf.shape[1]
    fill = out.shape[0] > 0
    zero = np.float32(0.0)
    n = 0
    for p in range(order.shape[0]):
        slot = order[p]
        for z in range(res):
            for y in range(res):
                for x in range(res):
                    if weight[slot, z, y, x] <= limit:
                        continue
                    t0 = tsdf[slot, z, y, x]
                    for a in range(3):
                        other, xx, yy, zz = slot, x, y, z
                        if a == 0:
                            xx += 1
                            if xx == res:
                                other, xx = after[p, 0], 0
                        elif a == 1:
                            yy += 1
                            if yy == res:
                                other, yy = after[p, 1], 0
                        else:
                            zz += 1
                            if zz == res:
                                other, zz = after[p, 2], 0
                        if other < 0 or weight[other, zz, yy, xx] <= limit:
                            continue
                        t1 = tsdf[other, zz, yy, xx]
                        if t0 * t1 < zero:
                            if fill:
                                ratio = (zero - t0) / (t1 - t0)
                                gx = np.float32(keys[slot, 0] * res + x)
                                gy = np.float32(keys[slot, 1] * res + y)
                                gz = np.float32(keys[slot, 2] * res + z)
                                if a == 0:
                                    gx += ratio
                                elif a == 1:
                                    gy += ratio
                                else:
                                    gz += ratio
                                out[n, 0] = voxel * gx
                                out[n, 1] = voxel * gy
                                out[n, 2] = voxel * gz
                            n += 1
    return n
