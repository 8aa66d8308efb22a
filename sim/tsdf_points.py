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

from sim.tsdf_blocks import block_arrays, upper_neighbours


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
    # For each block, the slot of the next block along x, y and z (-1: none), (B, 3).
    nearby = upper_neighbours(blocks)[:, [1, 2, 4]]
    after = np.where(nearby >= 0, blocks.order[nearby], -1)
    limit, voxel = np.float32(weight_threshold), np.float32(voxel_size)
    # A cheap count per block first, so that the points are written once, in place, and the
    # blocks without a crossing (many, in the truncation band around the surface) are skipped.
    counts = _block_counts(blocks.order, after, blocks.tsdf, blocks.weight, limit)
    ends = np.cumsum(counts)
    points = np.empty((int(ends[-1]), 3), dtype=np.float32)
    _crossings(blocks.keys, blocks.order, after, blocks.tsdf, blocks.weight, limit, voxel,
               counts, ends - counts, points)
    return points


@numba.njit(cache=True)
def _block_counts(order: npt.NDArray[np.int64], after: npt.NDArray[np.int64],
                  tsdf: npt.NDArray[np.float32], weight: npt.NDArray[np.float32],
                  limit: np.float32) -> npt.NDArray[np.int64]:  # pragma: no cover - numba
    """(B,) the number of crossings `_crossings` writes for each block in `order`: the same
    tests, pair by pair and without branches, axis by axis (the inner pairs, then the face
    shared with the next block)."""
    res = tsdf.shape[1]
    zero = np.float32(0.0)
    counts = np.zeros(order.shape[0], np.int64)
    for p in range(order.shape[0]):
        s = order[p]
        w, t = weight[s], tsdf[s]
        n = 0
        for z in range(res):
            for y in range(res):
                for x in range(res - 1):
                    n += (not w[z, y, x] <= limit) & (not w[z, y, x + 1] <= limit) \
                        & (t[z, y, x] * t[z, y, x + 1] < zero)
        for z in range(res):
            for y in range(res - 1):
                for x in range(res):
                    n += (not w[z, y, x] <= limit) & (not w[z, y + 1, x] <= limit) \
                        & (t[z, y, x] * t[z, y + 1, x] < zero)
        for z in range(res - 1):
            for y in range(res):
                for x in range(res):
                    n += (not w[z, y, x] <= limit) & (not w[z + 1, y, x] <= limit) \
                        & (t[z, y, x] * t[z + 1, y, x] < zero)
        o = after[p, 0]
        if o >= 0:
            for z in range(res):
                for y in range(res):
                    n += (not w[z, y, res - 1] <= limit) & (not weight[o, z, y, 0] <= limit) \
                        & (t[z, y, res - 1] * tsdf[o, z, y, 0] < zero)
        o = after[p, 1]
        if o >= 0:
            for z in range(res):
                for x in range(res):
                    n += (not w[z, res - 1, x] <= limit) & (not weight[o, z, 0, x] <= limit) \
                        & (t[z, res - 1, x] * tsdf[o, z, 0, x] < zero)
        o = after[p, 2]
        if o >= 0:
            for y in range(res):
                for x in range(res):
                    n += (not w[res - 1, y, x] <= limit) & (not weight[o, 0, y, x] <= limit) \
                        & (t[res - 1, y, x] * tsdf[o, 0, y, x] < zero)
        counts[p] = n
    return counts


@numba.njit(cache=True)
def _crossings(keys: npt.NDArray[np.int32], order: npt.NDArray[np.int64],
               after: npt.NDArray[np.int64], tsdf: npt.NDArray[np.float32],
               weight: npt.NDArray[np.float32], limit: np.float32, voxel: np.float32,
               counts: npt.NDArray[np.int64], starts: npt.NDArray[np.int64],
               out: npt.NDArray[np.float32]) -> None:  # pragma: no cover - numba
    """Writes each block's crossings to `out` from row `starts[p]`, voxel by voxel (z, y, x)
    and axis by axis, skipping the blocks `counts` gives none. Arithmetic in float32, as
    Open3D's."""
    res = tsdf.shape[1]
    zero = np.float32(0.0)
    for p in range(order.shape[0]):
        if counts[p] == 0:
            continue
        slot = order[p]
        n = starts[p]
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
        if n != starts[p] + counts[p]:
            raise RuntimeError("a block's crossings differ from its count")
