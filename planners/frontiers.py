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
def _grouped_voxels(frontier: npt.NDArray[np.bool_], lo: IndexArray, hi: IndexArray,
                    min_size: int) -> IndexArray:
    """(K, 3) indices, in C order, of the frontier voxels of the box [lo, hi) whose 26-connected
    group of frontier voxels inside the box has at least `min_size` voxels.

    The groups are grown from the frontier voxels only (a breadth-first search), so the cost
    follows the frontier's size in the box, not the box's volume."""
    sx, sy, sz = hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]
    group = np.zeros((sx, sy, sz), dtype=np.int32)  # 0: not yet reached
    sizes = [0]  # sizes[g]: voxels of group g
    queue = np.empty(sx * sy * sz, dtype=np.int64)
    kept = 0
    for x in range(sx):
        for y in range(sy):
            for z in range(sz):
                if group[x, y, z] != 0 or not frontier[lo[0] + x, lo[1] + y, lo[2] + z]:
                    continue
                g = len(sizes)
                group[x, y, z] = g
                queue[0] = (x * sy + y) * sz + z
                head, tail = 0, 1
                while head < tail:
                    q = queue[head]
                    head += 1
                    qx, qy, qz = q // (sy * sz), (q // sz) % sy, q % sz
                    for dx in range(max(qx - 1, 0), min(qx + 2, sx)):
                        for dy in range(max(qy - 1, 0), min(qy + 2, sy)):
                            for dz in range(max(qz - 1, 0), min(qz + 2, sz)):
                                if group[dx, dy, dz] == 0 and \
                                        frontier[lo[0] + dx, lo[1] + dy, lo[2] + dz]:
                                    group[dx, dy, dz] = g
                                    queue[tail] = (dx * sy + dy) * sz + dz
                                    tail += 1
                sizes.append(tail)
                if tail >= min_size:
                    kept += tail
    out = np.empty((kept, 3), dtype=np.int64)
    n = 0
    for x in range(sx):
        for y in range(sy):
            for z in range(sz):
                g = group[x, y, z]
                if g != 0 and sizes[g] >= min_size:
                    out[n, 0], out[n, 1], out[n, 2] = lo[0] + x, lo[1] + y, lo[2] + z
                    n += 1
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
