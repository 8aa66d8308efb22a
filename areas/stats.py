"""Measured statistics of an area (the paper's Table 1 columns) and the table itself.

Definitions (also in docs/areas.md):

- area (m²): footprint of the observable space, the xy projection of the observable voxels.
- volume (m³): the observable volume of the ground truth.
- bounding volume (m): extent of the mesh inside the area's bounds.
- levels: heights with a floor one can fly over. Upward-facing horizontal surfaces are sampled
  every 0.2 m; a sample counts when the voxel ``headroom`` metres above it is free (observable,
  or flyable for `flyable_voxels`). Counted samples are binned by height (0.1 m); bins holding at
  least 2 % of the footprint are grouped when closer than 0.35 m, and a group holding at least a
  quarter of the footprint is a level. Stair treads, desk tops and shelf boards never reach the
  2 % of a bin, so they never merge two floors or form one.
- faces: triangles of the mesh.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy import ndimage

from areas.area import Area, GroundTruth
from areas.ground_truth import blocked_voxels, sample_surface
from areas.observability import ViewModel, traversable

BoolArray = npt.NDArray[np.bool_]

LEVEL_SAMPLE_SPACING = 0.2
HEADROOM = 1.0
BIN = 0.1
BIN_FRACTION = 0.02
LEVEL_FRACTION = 0.25
GROUP_GAP = 0.35


@dataclass(frozen=True)
class TableRow:
    """One column of the paper's Table 1."""

    area_m2: float
    volume_m3: float
    bounding: tuple[float, float, float]
    rooms: int | None
    levels: int
    faces: int


TABLE1: dict[str, TableRow] = {
    "maze": TableRow(400, 1000, (20, 20, 2.5), None, 1, 130),
    "offices-a": TableRow(470, 1410, (22, 28, 3.4), 2, 1, 6910),
    "offices-b": TableRow(120, 1443, (8, 20, 12), 4, 4, 227_000),
    "offices-c": TableRow(534, 1602, (30, 16, 7.4), 23, 2, 857_000),
    "facility-a": TableRow(115, 690, (12, 14, 6), 1, 1, 373_000),
    "facility-b": TableRow(323, 1450, (19, 17, 4.6), 2, 1, 1_120_000),
    "facility-c": TableRow(478, 2868, (38, 22, 6), 5, 2, 1_072_000),
    "warehouse": TableRow(800, 9600, (40, 20, 12), 1, 2, 793_000),
    "platform-a": TableRow(384, 3456, (16, 24, 9), None, 3, 149_000),
    "platform-b": TableRow(480, 12000, (24, 20, 25), None, 3, 470_000),
    "powerplant": TableRow(1000, 26598, (33, 31, 26), None, 1, 2000),
}

# Orders of magnitude of the face counts the generators aim at (the table): the paper's
# exact counts come from CAD models; generated scenes match their order, capped near 1e6 faces
# because the simulator loads the mesh into pybullet and Open3D.
# MAZE keeps its strip-grid mesh (about 1600 triangles, no T-junctions), one order above the
# paper's 130 faces of merged quads.
FACE_ORDERS: dict[str, tuple[int, ...]] = {
    "maze": (2, 3), "offices-a": (4,), "offices-b": (5,), "offices-c": (6,), "facility-a": (5,),
    "facility-b": (6,), "facility-c": (6,), "warehouse": (5, 6), "platform-a": (5,),
    "platform-b": (5,), "powerplant": (3,),
}


@dataclass(frozen=True)
class AreaStats:
    """Statistics measured on a generated area.

    Attributes:
        level_heights: floor height of each level, metres, ascending.
    """

    area_m2: float
    volume_m3: float
    bounding: tuple[float, float, float]
    levels: int
    level_heights: tuple[float, ...]
    faces: int


def face_order(faces: int) -> int:
    """Order of magnitude of a face count: log10 rounded to the nearest integer."""
    return round(float(np.log10(max(faces, 1))))


def mesh_extent(area: Area) -> tuple[float, float, float]:
    """(x, y, z) extent in metres of the mesh clipped to the area's bounds."""
    lo = np.maximum(area.vertices.min(axis=0), area.bounds_min)
    hi = np.minimum(area.vertices.max(axis=0), area.bounds_max)
    size = hi - lo
    return float(size[0]), float(size[1]), float(size[2])


def flyable_voxels(area: Area) -> BoolArray:
    """(nx, ny, nz) bool: voxels the vehicle's centre can reach from the start, by the planners'
    clearance rule (`areas.observability`: the safety radius to every blocked voxel's cube)."""
    blocked = blocked_voxels(area)
    start = tuple(int(v) for v in np.floor((area.start.position - area.bounds_min)
                                           / area.voxel_size).astype(int))
    walkable = traversable(blocked, area.voxel_size, ViewModel().safety_radius_m)
    if not walkable[start]:
        return np.zeros_like(walkable)
    labels, _ = ndimage.label(walkable, structure=ndimage.generate_binary_structure(3, 1))
    return np.asarray(labels == labels[start])


def level_heights(area: Area, free: BoolArray) -> tuple[float, ...]:
    """Heights of the levels of ``area`` given a grid of ``free`` voxels (see the module doc)."""
    tri = area.triangles
    v = area.vertices
    normal = np.cross(v[tri[:, 1]] - v[tri[:, 0]], v[tri[:, 2]] - v[tri[:, 0]])
    length = np.linalg.norm(normal, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        up = normal[:, 2] > 0.99 * length
    points, _ = sample_surface(v, tri[up & (length > 0)], LEVEL_SAMPLE_SPACING,
                               np.random.default_rng(0))
    above = points + np.array([0.0, 0.0, HEADROOM])
    ijk = np.floor((above - area.bounds_min) / area.voxel_size).astype(np.int64)
    shape = np.array(area.grid_shape)
    inside = np.all((ijk >= 0) & (ijk < shape), axis=1)
    ok = np.zeros(len(points), dtype=bool)
    ok[inside] = free[tuple(ijk[inside].T)]
    z = points[ok, 2]
    if len(z) == 0:
        return ()
    footprint = float(area.extent[0] * area.extent[1])
    bins = np.round(z / BIN).astype(np.int64)
    values, counts = np.unique(bins, return_counts=True)
    weight = counts * LEVEL_SAMPLE_SPACING**2
    keep = weight >= BIN_FRACTION * footprint
    heights, weights = values[keep] * BIN, weight[keep]
    levels: list[float] = []
    group: list[int] = []
    for k in range(len(heights) + 1):
        if k < len(heights) and (not group or heights[k] - heights[group[-1]] < GROUP_GAP):
            group.append(k)
            continue
        if group and weights[group].sum() >= LEVEL_FRACTION * footprint:
            levels.append(float(np.average(heights[group], weights=weights[group])))
        group = [k]
    return tuple(levels)


def measure(area: Area, truth: GroundTruth) -> AreaStats:
    """Table 1 statistics of ``area`` measured from its mesh and ground truth."""
    vs = area.voxel_size
    heights = level_heights(area, truth.observable)
    return AreaStats(
        area_m2=float(np.count_nonzero(truth.observable.any(axis=2))) * vs**2,
        volume_m3=truth.observable_volume_m3,
        bounding=mesh_extent(area),
        levels=len(heights),
        level_heights=heights,
        faces=len(area.triangles),
    )
