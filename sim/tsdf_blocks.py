"""The TSDF's voxel blocks: the Open3D `VoxelBlockGrid` that holds them, and its buffers as
arrays for compiled code, without copies, its blocks sorted by key so that a block is found by
binary search."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numba
import numpy as np
import numpy.typing as npt

from sim.open3d_any import o3c, o3d

_CPU = o3c.Device("CPU:0")


def block_grid(voxel_size: float, resolution: int, block_count: int) -> Any:
    """An empty CPU `VoxelBlockGrid` with float32 "tsdf" and "weight" per voxel."""
    return o3d.t.geometry.VoxelBlockGrid(
        attr_names=("tsdf", "weight"), attr_dtypes=(o3c.float32, o3c.float32),
        attr_channels=((1), (1)), voxel_size=voxel_size, block_resolution=resolution,
        block_count=block_count, device=_CPU,
    )


@dataclass(frozen=True)
class BlockArrays:
    """One moment of a grid, without copies (valid until the grid next changes).

    Attributes:
        keys: (capacity, 3) int32 block key of each slot (blocks of R³ voxels; the voxel
            (i, j, k) of block key b is the sample at (b * R + (i, j, k)) * voxel size).
        tsdf: (capacity, R, R, R) float32 normalised signed distance, indexed [slot, z, y, x].
        weight: (capacity, R, R, R) float32 fusion weight, the same layout.
        order: (B,) int64 slots of the B allocated blocks, sorted by key.
        sorted_keys: (B,) int64 the keys in that order, flattened (`flat_keys`).
        origin: (3,) int64 and span (3,) int64: the flattening, `flat_keys` below.
    """

    keys: npt.NDArray[np.int32]
    tsdf: npt.NDArray[np.float32]
    weight: npt.NDArray[np.float32]
    order: npt.NDArray[np.int64]
    sorted_keys: npt.NDArray[np.int64]
    origin: npt.NDArray[np.int64]
    span: npt.NDArray[np.int64]


def block_arrays(grid: Any) -> BlockArrays | None:
    """The blocks of an Open3D CPU `VoxelBlockGrid` with float32 "tsdf" and "weight"; None
    when it has none."""
    table = grid.hashmap()
    slots = table.active_buf_indices().numpy().astype(np.int64)
    if len(slots) == 0:
        return None
    keys = table.key_tensor().numpy()
    tsdf = grid.attribute("tsdf").numpy()
    weight = grid.attribute("weight").numpy()
    res = tsdf.shape[1]
    shape = (tsdf.shape[0], res, res, res)
    used = keys[slots].astype(np.int64)
    # One block of margin on each side: a neighbour's key flattens inside the span too.
    origin = used.min(axis=0) - 1
    span = used.max(axis=0) + 2 - origin
    flat = flat_keys(used, origin, span)
    rank = np.argsort(flat)
    return BlockArrays(keys, tsdf.reshape(shape), weight.reshape(shape), slots[rank],
                       flat[rank], origin, span)


def flat_keys(keys: npt.NDArray[np.int64], origin: npt.NDArray[np.int64],
              span: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
    """(N,) one integer per block key (N, 3) within `origin + [0, span)`, in key order."""
    rel = keys - origin
    return (rel[:, 0] * span[1] + rel[:, 1]) * span[2] + rel[:, 2]


def upper_neighbours(blocks: BlockArrays) -> npt.NDArray[np.int64]:
    """(B, 8): for each block in key order (`blocks.order`), the position in that order of the
    block at offset (k & 1, (k >> 1) & 1, (k >> 2) & 1) from it (k = 0 is the block itself; 1,
    2 and 4 the next along x, y and z), -1 where none is allocated. The keys' flattening keeps
    a block of margin, so an offset key stays inside it."""
    span = blocks.span
    step = np.array([span[1] * span[2], span[2], 1], dtype=np.int64)
    found = np.full((len(blocks.order), 8), -1, dtype=np.int64)
    for k in range(8):
        wanted = blocks.sorted_keys + (k & 1) * step[0] + (k >> 1 & 1) * step[1] + (k >> 2 & 1)
        at = np.searchsorted(blocks.sorted_keys, wanted)
        inside = at < len(blocks.sorted_keys)
        hit = np.zeros(len(wanted), dtype=bool)
        hit[inside] = blocks.sorted_keys[at[inside]] == wanted[inside]
        found[hit, k] = at[hit]
    return found


@numba.njit(cache=True)
def slot_of(sorted_keys: npt.NDArray[np.int64], order: npt.NDArray[np.int64],
            origin: npt.NDArray[np.int64], span: npt.NDArray[np.int64], bx: int, by: int,
            bz: int) -> int:  # pragma: no cover - numba
    """The slot of block (bx, by, bz), -1 when it is not allocated."""
    rx, ry, rz = bx - origin[0], by - origin[1], bz - origin[2]
    if rx < 0 or ry < 0 or rz < 0 or rx >= span[0] or ry >= span[1] or rz >= span[2]:
        return -1
    wanted = (rx * span[1] + ry) * span[2] + rz
    i = np.searchsorted(sorted_keys, wanted)
    if i < sorted_keys.shape[0] and sorted_keys[i] == wanted:
        return order[i]
    return -1
