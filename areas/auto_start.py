"""The automatic start pose of an imported area, and what its free space says about the area.

The blocked voxels of the ground truth (centres within half a voxel of the mesh) split the grid
into 6-connected free components. In each, the vehicle can reach the traversable voxels
(`areas.observability`: its centre keeps the safety radius from every blocked cube) connected to
its start. The largest component that does not touch the outer faces of the grid (an inside) is
chosen if it holds at least `INDOOR_MIN_FRACTION` of the largest component's volume and room for
the vehicle; otherwise the largest component with room for the vehicle. In it the start lies in
the largest set of traversable voxels the vehicle can fly between, at the voxel centre with the
largest distance to the mesh and to the grid's faces, among those 1-2 m above the floor below
them and within `START_REACH` of the mesh (so the camera sees the structure from the first
frame) where any are, else among all. Yaw 0. The component's volume, the vehicle's reachable
volume and its distinct floor heights (levels) come with the start, and the area's indoor /
outdoor class: indoor when at least `INDOOR_MIN_COVERED` of the space the vehicle reaches has
a surface somewhere above it (a roof, a ceiling, a deck), outdoor otherwise. On the built-in
areas this gives Table 1's class for every one (indoors all of the reachable space is covered;
PLATFORM A 47 %, PLATFORM B 36 %, POWERPLANT under 1 %), and a building with an open door or
window stays indoor.

A mesh whose openings are all narrower than the vehicle leaves it almost no reachable space:
`choose_start` refuses it (`MIN_REACHABLE_M3`), saying so, rather than giving an area no run
can explore.
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
from areas.observability import ViewModel, traversable

BoolArray = npt.NDArray[np.bool_]

# The camera's range (5 m) less a metre: from the start, some structure is in view.
START_REACH = 4.0
# Less reachable space than this (m³) is no area to explore: about a 1.2 m cube.
MIN_REACHABLE_M3 = 2.0
PREFERRED_HEIGHT = (1.0, 2.0)  # metres above the floor below the start
INDOOR_MIN_FRACTION = 0.25  # of the largest component's volume, for an inside to be chosen
INDOOR_MIN_COVERED = 0.5  # of the reachable volume under a surface, for an area to be indoor
EXACT_CANDIDATES = 20_000  # voxels whose exact clearance is computed
STOREY_MIN_GAP = 2.0  # metres between two floor heights counted as distinct levels
STOREY_MIN_FRACTION = 0.25  # of the largest floor area, for a floor height to count as a level


@dataclass(frozen=True)
class AutoStart:
    """What the free-space analysis found: the start and the statistics of its component."""

    start: StartPose
    volume_m3: float
    reachable_volume_m3: float
    levels: int
    indoor: bool


def choose_start(area: Area) -> AutoStart:
    """The automatic start pose and the statistics of its free component (the module docstring).

    Raises:
        MeshImportError: when no free space has room for the vehicle, or the space it can reach
            from any start is almost empty.
    """
    vs = area.voxel_size
    blocked = blocked_voxels(area)
    six = ndimage.generate_binary_structure(3, 1)
    labels, count = ndimage.label(~blocked, structure=six)
    radius = ViewModel().safety_radius_m
    walkable = traversable(blocked, vs, radius)
    if count == 0 or not walkable.any():
        raise MeshImportError(f"no free space has room for the vehicle ({radius:g} m from every "
                              "surface): the mesh leaves no gap that wide")
    sizes = np.bincount(labels.ravel(), minlength=count + 1)
    sizes[0] = 0
    roomy = np.bincount(labels[walkable], minlength=count + 1) > 0
    roomy[0] = False

    faces = [labels[0], labels[-1], labels[:, 0], labels[:, -1], labels[:, :, 0], labels[:, :, -1]]
    touching = np.zeros(count + 1, dtype=bool)
    touching[np.unique(np.concatenate([f.ravel() for f in faces]))] = True
    inside = roomy & ~touching & (sizes >= INDOOR_MIN_FRACTION * sizes.max())
    pool = inside if inside.any() else roomy
    chosen = int(np.argmax(np.where(pool, sizes, -1)))
    component = labels == chosen
    del labels

    reachable = _largest_component(walkable & component, six)
    reachable_m3 = float(np.count_nonzero(reachable)) * vs**3
    free_m3 = float(sizes[chosen]) * vs**3
    if reachable_m3 < MIN_REACHABLE_M3:
        raise MeshImportError(
            f"the vehicle can reach only {reachable_m3:.2f} m³ of the {free_m3:.1f} m³ of free "
            f"space: the mesh's openings are narrower than the vehicle needs ({2 * radius:g} m, "
            f"its safety radius on both sides)")
    height = _height_above_floor(blocked) * vs
    start_ijk = _best_voxel(area, blocked, reachable, height)
    position = area.bounds_min + (np.asarray(start_ijk, dtype=np.float64) + 0.5) * vs
    return AutoStart(
        start=StartPose(position=position, yaw=0.0),
        volume_m3=free_m3,
        reachable_volume_m3=reachable_m3,
        levels=_count_levels(component, blocked, vs),
        indoor=covered_fraction(blocked, reachable) >= INDOOR_MIN_COVERED,
    )


def covered_fraction(blocked: BoolArray, space: BoolArray) -> float:
    """The share of the voxels of `space` that have a blocked voxel somewhere above them (+z)."""
    if not space.any():
        return 0.0
    # Blocked at or above each voxel, then shifted down one: blocked strictly above.
    at_or_above = np.flip(np.logical_or.accumulate(np.flip(blocked, axis=2), axis=2), axis=2)
    above = np.zeros_like(blocked)
    above[:, :, :-1] = at_or_above[:, :, 1:]
    return float(np.count_nonzero(above & space)) / float(np.count_nonzero(space))


def _largest_component(mask: BoolArray, structure: npt.NDArray[np.bool_]) -> BoolArray:
    """The largest 6-connected component of a non-empty ``mask``."""
    labels, count = ndimage.label(mask, structure=structure)
    sizes = np.bincount(labels.ravel(), minlength=count + 1)
    sizes[0] = 0
    largest: BoolArray = labels == int(np.argmax(sizes))
    return largest


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


def _best_voxel(area: Area, blocked: BoolArray, reachable: BoolArray,
                height: FloatArray) -> tuple[int, int, int]:
    """Voxel of the non-empty ``reachable`` with the largest exact clearance, preferring those
    1-2 m above a floor and within `START_REACH` of the mesh.

    ``height`` is in metres. The voxel estimate of the clearance (distance to the nearest blocked
    voxel centre or grid face) preselects the `EXACT_CANDIDATES` most promising voxels within
    reach; the exact distance to the mesh and to the grid's faces decides among them.
    """
    vs = area.voxel_size
    padded = np.pad(~blocked, 1, constant_values=False)
    estimate = ndimage.distance_transform_edt(padded)[1:-1, 1:-1, 1:-1] * vs - 0.5 * vs
    candidates = np.argwhere(reachable)
    h = height[tuple(candidates.T)]
    near = estimate[tuple(candidates.T)] <= START_REACH + vs
    preferred = (h >= PREFERRED_HEIGHT[0]) & (h <= PREFERRED_HEIGHT[1])
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor.from_numpy((area.vertices - area.bounds_min).astype(np.float32)),
        o3d.core.Tensor.from_numpy(np.ascontiguousarray(area.triangles, dtype=np.uint32)),
    )
    for pool in (candidates[preferred & near], candidates[near], candidates):
        if len(pool) == 0:
            continue
        pool_estimate = estimate[tuple(pool.T)]
        top = pool[np.argsort(-pool_estimate, kind="stable")[:EXACT_CANDIDATES]]
        centres = (top + 0.5) * vs  # grid frame
        to_mesh = scene.compute_distance(
            o3d.core.Tensor.from_numpy(centres.astype(np.float32))
        ).numpy().astype(np.float64)
        to_faces = np.minimum(centres, area.extent - centres).min(axis=1)
        exact = np.where(to_mesh <= START_REACH, np.minimum(to_mesh, to_faces), -np.inf)
        if np.isfinite(exact).any() or pool is candidates:
            best = int(np.argmax(np.where(np.isfinite(exact), exact,
                                          np.minimum(to_mesh, to_faces) - 1e9)))
            i, j, k = (int(v) for v in top[best])
            return i, j, k
    raise AssertionError("reachable is not empty")


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
