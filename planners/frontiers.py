"""Frontiers for planners: the clusters the framework keeps (with centroid and mean normal, see
`sim.frontiers.FrontierTracker`) and the frontier voxels inside the camera's current view.
"""

from __future__ import annotations

import numba
import numpy as np
import numpy.typing as npt

from planners.search import IndexArray
from sim.camera import CameraConfig
from sim.geometry import Pose
from sim.map_view import FrontierCluster, MapView

__all__ = ["FrontierCluster", "clusters", "frontiers_in_view"]

FloatArray = npt.NDArray[np.float64]


def clusters(view: MapView, min_size: int) -> list[FrontierCluster]:
    """Frontier clusters of at least `min_size` voxels, each with its voxel indices, centroid
    (world) and mean normal pointing into the unknown; kept up to date by the framework."""
    return view.frontier_clusters(min_size)


@numba.njit(cache=True)
def _neighbour_offsets(ny: int, nz: int) -> IndexArray:
    """(26,) flat C-order offsets of a voxel's 26 neighbours in a grid of (.., ny, nz)."""
    offsets = np.empty(26, dtype=np.int64)
    n = 0
    for dx in range(-1, 2):
        for dy in range(-1, 2):
            for dz in range(-1, 2):
                if dx != 0 or dy != 0 or dz != 0:
                    offsets[n] = (dx * ny + dy) * nz + dz
                    n += 1
    return offsets


@numba.njit(cache=True)
def _grouped_voxels(frontier: npt.NDArray[np.bool_], lo: IndexArray, hi: IndexArray,
                    min_size: int) -> IndexArray:
    """(K, 3) indices, in C order, of the frontier voxels of the box [lo, hi) whose 26-connected
    group of frontier voxels inside the box has at least `min_size` voxels.

    The box is copied once into a flat label grid with a one-voxel border of zeros (-1 marks a
    frontier voxel not yet reached, g > 0 its group), so a neighbour is one read at a fixed
    offset, with no bounds to test. Groups are grown breadth-first from the frontier voxels as
    the scan meets them in C order, which also lists the voxels in C order: the output is read
    off that list, not off a second scan of the box."""
    sx, sy, sz = hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]
    py, pz = sy + 2, sz + 2
    label = np.zeros((sx + 2) * py * pz, dtype=np.int32)
    count = 0
    for x in range(sx):
        for y in range(sy):
            row = frontier[lo[0] + x, lo[1] + y, lo[2]:hi[2]]
            base = ((x + 1) * py + y + 1) * pz + 1
            for z in range(sz):
                label[base + z] = -np.int32(row[z])
                count += row[z]
    offsets = _neighbour_offsets(py, pz)
    sizes = [0]  # sizes[g]: voxels of group g
    queue = np.empty(count, dtype=np.int64)
    cells = np.empty(count, dtype=np.int64)  # the frontier voxels' labels' positions, C order
    n = 0
    kept = 0
    for x in range(sx):
        for y in range(sy):
            row = frontier[lo[0] + x, lo[1] + y, lo[2]:hi[2]]
            base = ((x + 1) * py + y + 1) * pz + 1
            for z in range(sz):
                if not row[z]:
                    continue
                p = base + z
                if label[p] == -1:
                    g = np.int32(len(sizes))
                    label[p] = g
                    queue[0] = p
                    head, tail = 0, 1
                    while head < tail:
                        q = queue[head]
                        head += 1
                        for o in range(26):
                            r = q + offsets[o]
                            if label[r] == -1:
                                label[r] = g
                                queue[tail] = r
                                tail += 1
                    sizes.append(tail)
                    if tail >= min_size:
                        kept += tail
                cells[n] = p
                n += 1
    out = np.empty((kept, 3), dtype=np.int64)
    m = 0
    for c in range(count):
        p = cells[c]
        if sizes[label[p]] >= min_size:
            q = p // pz
            out[m, 0] = lo[0] + q // py - 1
            out[m, 1] = lo[1] + q % py - 1
            out[m, 2] = lo[2] + p % pz - 1
            m += 1
    return out


def frontiers_in_view(
    view: MapView, pose: Pose, camera: CameraConfig, max_range_m: float | None = None,
    min_group_size: int = 1,
) -> tuple[IndexArray, FloatArray]:
    """Frontier voxels whose centres lie in the camera frustum of a level `pose`.

    Only the box of the sensor range around the pose is scanned, so the cost does not grow
    with the area. With `min_group_size`, voxels of 26-connected frontier groups smaller than
    that inside the box are left out (isolated frontier voxels are mostly sensor noise); the
    groups are labelled in the box only, far cheaper than clustering the whole map.

    Returns:
        (F, 3) int64 voxel indices and (F, 3) float64 offsets of their centres from the pose
        position (world metres), F >= 0.
    """
    reach = camera.max_range_m if max_range_m is None else max_range_m
    here = np.asarray(pose.position, dtype=np.float64)
    lo = np.maximum(view.world_to_index((here - reach)[None])[0], 0)
    hi = np.minimum(view.world_to_index((here + reach)[None])[0] + 1, np.array(view.shape))
    if np.any(hi <= lo):
        return np.zeros((0, 3), dtype=np.int64), np.zeros((0, 3))
    if min_group_size > 1:
        idx = _grouped_voxels(view.frontier, lo.astype(np.int64), hi.astype(np.int64),
                              min_group_size)
    else:
        idx = np.argwhere(view.frontier[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]]) + lo
    if len(idx) == 0:
        return idx.astype(np.int64), np.zeros((0, 3))
    offsets = view.index_to_world(idx) - here
    c, s = np.cos(pose.yaw), np.sin(pose.yaw)
    forward = offsets[:, 0] * c + offsets[:, 1] * s
    left = -offsets[:, 0] * s + offsets[:, 1] * c
    up = offsets[:, 2]
    half_h = np.radians(camera.fov_h_deg) / 2.0
    half_v = np.radians(camera.fov_v_deg) / 2.0
    dist = np.linalg.norm(offsets, axis=1)
    inside = (
        (forward > 0.0)
        & (np.abs(left) <= forward * np.tan(half_h))
        & (np.abs(up) <= forward * np.tan(half_v))
        & (dist <= reach)
        & (dist >= camera.min_range_m)
    )
    return idx[inside].astype(np.int64), offsets[inside]
