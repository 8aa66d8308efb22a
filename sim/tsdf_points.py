"""The fused surface as points: where the signed distance changes sign between two neighbouring
voxel samples, interpolated linearly along that axis. The points of Open3D's
`VoxelBlockGrid.extract_point_cloud`, computed in one compiled pass (a sixth of its time on
one thread), in an order fixed by the blocks' keys rather than by Open3D's threads."""

from __future__ import annotations

from typing import Any

import numba
import numpy as np
import numpy.typing as npt


def crossing_points(grid: Any, voxel_size: float,
                    weight_threshold: float) -> npt.NDArray[np.float32]:
    """(N, 3) float32 metres: every sign change of the TSDF between voxels whose weights both
    exceed `weight_threshold`, along +x, +y and +z, blocks in key order.

    Args:
        grid: an Open3D CPU `VoxelBlockGrid` with float32 "tsdf" and "weight" attributes.
        voxel_size: its voxel edge, metres.
    """
    table = grid.hashmap()
    slots = table.active_buf_indices().numpy().astype(np.int64)
    if len(slots) == 0:
        return np.zeros((0, 3), dtype=np.float32)
    keys = table.key_tensor().numpy()
    # Views of the grid's own buffers, (capacity, R, R, R, 1) with x fastest: no copy.
    tsdf = grid.attribute("tsdf").numpy()
    weight = grid.attribute("weight").numpy()
    res = tsdf.shape[1]
    shape = (tsdf.shape[0], res, res, res)
    tsdf, weight = tsdf.reshape(shape), weight.reshape(shape)
    order, after = _blocks_in_key_order(np.ascontiguousarray(keys[slots]), slots)
    limit = np.float32(weight_threshold)
    voxel = np.float32(voxel_size)
    empty = np.zeros((0, 3), dtype=np.float32)
    count = _crossings(keys, order, after, tsdf, weight, limit, voxel, empty)
    points = np.empty((count, 3), dtype=np.float32)
    _crossings(keys, order, after, tsdf, weight, limit, voxel, points)
    return points


@numba.njit(cache=True)
def _blocks_in_key_order(
    keys: npt.NDArray[np.int32], slots: npt.NDArray[np.int64]
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:  # pragma: no cover - numba
    """The slots of blocks `keys` (B, 3) sorted by key, and for each the slot of the block after
    it along x, y and z (-1: none), (B, 3)."""
    count = keys.shape[0]
    lo = np.empty(3, np.int64)
    span = np.empty(3, np.int64)
    for a in range(3):
        lo[a] = keys[:, a].min() - 1
        span[a] = keys[:, a].max() + 2 - lo[a]
    flat = np.empty(count, np.int64)
    for b in range(count):
        flat[b] = ((keys[b, 0] - lo[0]) * span[1] + (keys[b, 1] - lo[1])) * span[2] \
            + (keys[b, 2] - lo[2])
    rank = np.argsort(flat)
    sorted_flat = flat[rank]
    steps = np.array([span[1] * span[2], span[2], 1])
    order = slots[rank]
    after = np.full((count, 3), -1, np.int64)
    for p in range(count):
        for a in range(3):
            wanted = sorted_flat[p] + steps[a]
            i = np.searchsorted(sorted_flat, wanted)
            if i < count and sorted_flat[i] == wanted:
                after[p, a] = order[i]
    return order, after


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
