"""The automatic start pose of an imported area, and what its free space says about the area.

The blocked voxels of the ground truth (centres within half a voxel of the mesh) split the grid
into 6-connected free components. The largest component that does not touch the outer faces of
the grid (an inside) is chosen if it holds at least `INDOOR_MIN_FRACTION` of the largest
component's volume and room for the vehicle; otherwise the largest component with room for the
vehicle. In it the start is the voxel centre with the largest distance to the mesh and to the
grid's faces, among those 1-2 m above the floor below them if any has at least `MIN_CLEARANCE`,
else among all. Yaw 0. The component's volume and its distinct floor heights (levels) come with
the start.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import open3d as o3d
from scipy import ndimage

from areas.area import Area, StartPose
from areas.ground_truth import blocked_voxels
from areas.mesh import FloatArray
from areas.mesh_file import MeshImportError

BoolArray = npt.NDArray[np.bool_]

MIN_CLEARANCE = 0.5  # metres from the start to the mesh and to the grid's faces
PREFERRED_HEIGHT = (1.0, 2.0)  # metres above the floor below the start
INDOOR_MIN_FRACTION = 0.25  # of the largest component's volume, for an inside to be chosen
EXACT_CANDIDATES = 20_000  # voxels whose exact clearance is computed
STOREY_MIN_GAP = 2.0  # metres between two floor heights counted as distinct levels
STOREY_MIN_FRACTION = 0.25  # of the largest floor area, for a floor height to count as a level


@dataclass(frozen=True)
class AutoStart:
    """What the free-space analysis found: the start and the statistics of its component."""

    start: StartPose
    volume_m3: float
    levels: int
    indoor: bool


def choose_start(area: Area) -> AutoStart:
    """The automatic start pose and the statistics of its free component (the module docstring).

    Raises:
        MeshImportError: when no free space has `MIN_CLEARANCE` for a start.
    """
    vs = area.voxel_size
    blocked = blocked_voxels(area)
    free = ~blocked
    six = ndimage.generate_binary_structure(3, 1)
    labels, count = ndimage.label(free, structure=six)
    if count == 0:
        raise MeshImportError(f"no free space with {MIN_CLEARANCE} m clearance")
    sizes = np.bincount(labels.ravel(), minlength=count + 1)
    sizes[0] = 0

    # Clearance estimate: distance to the nearest blocked voxel centre or to the grid's faces.
    padded = np.pad(free, 1, constant_values=False)
    clearance = ndimage.distance_transform_edt(padded)[1:-1, 1:-1, 1:-1] * vs - 0.5 * vs
    roomy = np.bincount(labels[clearance >= MIN_CLEARANCE], minlength=count + 1) > 0
    roomy[0] = False
    if not roomy.any():
        raise MeshImportError(f"no free space with {MIN_CLEARANCE} m clearance")

    faces = [labels[0], labels[-1], labels[:, 0], labels[:, -1], labels[:, :, 0], labels[:, :, -1]]
    touching = np.zeros(count + 1, dtype=bool)
    touching[np.unique(np.concatenate([f.ravel() for f in faces]))] = True
    inside = roomy & ~touching & (sizes >= INDOOR_MIN_FRACTION * sizes.max())
    pool = inside if inside.any() else roomy
    chosen = int(np.argmax(np.where(pool, sizes, -1)))
    component = labels == chosen

    height = _height_above_floor(blocked) * vs
    start_ijk = _best_voxel(area, component, clearance, height)
    if start_ijk is None:
        raise MeshImportError(f"no free space with {MIN_CLEARANCE} m clearance")
    position = area.bounds_min + (np.asarray(start_ijk, dtype=np.float64) + 0.5) * vs
    return AutoStart(
        start=StartPose(position=position, yaw=0.0),
        volume_m3=float(sizes[chosen]) * vs**3,
        levels=_count_levels(component, blocked, vs),
        indoor=not bool(touching[chosen]),
    )


def _height_above_floor(blocked: BoolArray) -> FloatArray:
    """(nx, ny, nz) voxel edges from each voxel centre down to the top of the blocked voxel below.

    With nothing blocked below, the bottom of the grid is the floor.
    """
    nz = blocked.shape[2]
    k = np.arange(nz)
    last = np.maximum.accumulate(np.where(blocked, k, -1), axis=2)
    # For voxel k the floor is the last blocked voxel strictly below: shift by one layer.
    below = np.concatenate([np.full((*blocked.shape[:2], 1), -1), last[:, :, :-1]], axis=2)
    # Centre of voxel k at k + 0.5, top of the floor voxel at below + 1 (the grid bottom at 0).
    return (k - below - 0.5).astype(np.float64)


def _best_voxel(
    area: Area, component: BoolArray, clearance: FloatArray, height: FloatArray
) -> tuple[int, int, int] | None:
    """Voxel of ``component`` with the largest exact clearance, preferring 1-2 m above a floor.

    The voxel estimate of the clearance preselects the `EXACT_CANDIDATES` most promising voxels;
    the exact distance to the mesh and to the grid's faces decides among them.
    """
    vs = area.voxel_size
    candidates = np.argwhere(component & (clearance >= MIN_CLEARANCE - vs))
    if len(candidates) == 0:
        return None
    h = height[tuple(candidates.T)] * vs
    preferred = (h >= PREFERRED_HEIGHT[0]) & (h <= PREFERRED_HEIGHT[1])
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor.from_numpy((area.vertices - area.bounds_min).astype(np.float32)),
        o3d.core.Tensor.from_numpy(np.ascontiguousarray(area.triangles, dtype=np.uint32)),
    )
    for pool in (candidates[preferred], candidates):
        if len(pool) == 0:
            continue
        pool_estimate = clearance[tuple(pool.T)]
        top = pool[np.argsort(-pool_estimate, kind="stable")[:EXACT_CANDIDATES]]
        centres = (top + 0.5) * vs  # grid frame
        to_mesh = scene.compute_distance(
            o3d.core.Tensor.from_numpy(centres.astype(np.float32))
        ).numpy().astype(np.float64)
        to_faces = np.minimum(centres, area.extent - centres).min(axis=1)
        exact = np.minimum(to_mesh, to_faces)
        best = int(np.argmax(exact))
        if exact[best] >= MIN_CLEARANCE:
            i, j, k = (int(v) for v in top[best])
            return i, j, k
    return None


def _count_levels(component: BoolArray, blocked: BoolArray, vs: float) -> int:
    """Distinct floor heights of a component: layers whose floor area is at least
    `STOREY_MIN_FRACTION` of the largest, counted when `STOREY_MIN_GAP` above the last counted."""
    on_floor = component.copy()
    on_floor[:, :, 1:] &= blocked[:, :, :-1]
    on_floor[:, :, 0] = False
    area_per_layer = on_floor.sum(axis=(0, 1))
    if area_per_layer.max() == 0:
        return 1
    layers = np.nonzero(area_per_layer >= STOREY_MIN_FRACTION * area_per_layer.max())[0]
    levels, last = 0, -np.inf
    for k in layers:
        if (float(k) - last) * vs >= STOREY_MIN_GAP:
            levels += 1
            last = float(k)
    return max(levels, 1)
