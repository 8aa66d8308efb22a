"""The TSDF read at arbitrary points: trilinear between the eight voxel samples around each,
in one compiled pass over the points (the recall over time reads 20,000 points every 20 s)."""

from __future__ import annotations

from typing import Any

import numba
import numpy as np
import numpy.typing as npt

from sim.tsdf_blocks import block_arrays, slot_of


def trilinear(grid: Any, points: npt.NDArray[np.floating], voxel_size: float) -> tuple[
    npt.NDArray[np.float64], npt.NDArray[np.float32]
]:
    """The normalised signed distance at each of `points` (N, 3) metres, trilinear between the
    8 voxel samples around it, and the least weight among those samples; NaN and 0 where one
    is not allocated or has no weight.

    Args:
        grid: an Open3D CPU `VoxelBlockGrid` with float32 "tsdf" and "weight" attributes.
        voxel_size: its voxel edge, metres.
    """
    n = len(points)
    sdf = np.full(n, np.nan)
    weight = np.zeros(n, dtype=np.float32)
    blocks = block_arrays(grid)
    if blocks is None or n == 0:
        return sdf, weight
    # Voxel (i, j, k) holds the field sampled at (i, j, k) * voxel_size.
    scaled = np.asarray(points, dtype=np.float64).reshape(-1, 3) / voxel_size
    _trilinear(scaled, blocks.tsdf, blocks.weight, blocks.order,
               blocks.sorted_keys, blocks.origin, blocks.span, sdf, weight)
    return sdf, weight


@numba.njit(cache=True)
def _trilinear(scaled: npt.NDArray[np.float64], tsdf: npt.NDArray[np.float32],
               weight: npt.NDArray[np.float32],
               order: npt.NDArray[np.int64], sorted_keys: npt.NDArray[np.int64],
               origin: npt.NDArray[np.int64], span: npt.NDArray[np.int64],
               sdf: npt.NDArray[np.float64],
               least: npt.NDArray[np.float32]) -> None:  # pragma: no cover - numba
    """Fills `sdf` and `least` where all eight samples are allocated with weight; the corners
    in (x, y, z) binary order, each weighted by the product of its three axis factors."""
    res = tsdf.shape[1]
    for p in range(scaled.shape[0]):
        bx = np.floor(scaled[p, 0])
        by = np.floor(scaled[p, 1])
        bz = np.floor(scaled[p, 2])
        fx, fy, fz = scaled[p, 0] - bx, scaled[p, 1] - by, scaled[p, 2] - bz
        ix, iy, iz = int(bx), int(by), int(bz)
        # The block of the lower corner; a corner past its last voxel asks for a neighbour.
        kx, ky, kz = ix // res, iy // res, iz // res
        home = slot_of(sorted_keys, order, origin, span, kx, ky, kz)
        total = 0.0
        w_min = np.float32(np.inf)
        for corner in range(8):
            ox, oy, oz = corner >> 2, (corner >> 1) & 1, corner & 1
            lx, ly, lz = ix + ox - kx * res, iy + oy - ky * res, iz + oz - kz * res
            slot = home
            if lx == res or ly == res or lz == res:
                slot = slot_of(sorted_keys, order, origin, span, kx + lx // res,
                               ky + ly // res, kz + lz // res)
                lx, ly, lz = lx % res, ly % res, lz % res
            value = 0.0
            w = np.float32(0.0)
            if slot >= 0:
                value = np.float64(tsdf[slot, lz, ly, lx])
                w = weight[slot, lz, ly, lx]
            ax = fx if ox == 1 else 1.0 - fx
            ay = fy if oy == 1 else 1.0 - fy
            az = fz if oz == 1 else 1.0 - fz
            total += ax * ay * az * value
            w_min = min(w_min, w)
        if w_min > 0:
            sdf[p] = total
            least[p] = w_min
