"""Import a user's triangle mesh (OBJ, PLY, STL, OFF, GLB/GLTF, COLLADA) as an `Area`.

Pipeline (`import_mesh`; steps 2 to 4 are `areas.mesh_file`'s, steps 6 and 7 use
`areas.auto_start`):

1. Checks on the request: the area name, the scale, the file extension and the file size.
2. Loading with trimesh (scenes are flattened with their node transforms applied), after a cheap
   check of the file signature so that garbage bytes are reported as unreadable rather than as an
   empty mesh.
3. Units: COLLADA's ``<asset><unit meter="...">`` is read from the XML and applied (trimesh keeps
   the file's units), then the user's ``scale``, then a rotation taking the ``up`` axis to +z.
4. Cleaning: degenerate faces (repeated indices or zero area) and unreferenced vertices are dropped.
5. Bounds: the mesh's bounding box grown by one voxel plus `HORIZONTAL_MARGIN` on each horizontal
   side and by `TOP_MARGIN` above (not below: the floor is the bottom of the grid), snapped outward
   to whole voxels. World coordinates are kept as they are.
6. Start pose (when not given, `areas.auto_start`): in the largest inside free component (or the
   largest component) with room for the vehicle, the traversable voxel the vehicle can reach
   (the planners' clearance rule) with the most clearance, 1-2 m above a floor and within 4 m of
   the mesh where possible. A mesh whose openings are all narrower than the vehicle is refused,
   with the reachable volume and the reason. Yaw 0.
7. Plateau time (when not given): ``clamp(0.8 s/m³ × volume of the chosen component, 300, 1800)``
   seconds, the free volume a perfect exploration could fly through.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from areas.area import Area, AreaInfo, StartPose
from areas.auto_start import (
    EXACT_CANDIDATES,
    INDOOR_MIN_FRACTION,
    MIN_REACHABLE_M3,
    PREFERRED_HEIGHT,
    START_REACH,
    STOREY_MIN_FRACTION,
    STOREY_MIN_GAP,
    choose_start,
)
from areas.mesh import FloatArray, IntArray
from areas.mesh_file import (
    SUPPORTED_EXTENSIONS,
    MeshImportError,
    drop_degenerate_faces,
    load_mesh_file,
)

__all__ = [
    "EXACT_CANDIDATES",
    "HORIZONTAL_MARGIN",
    "INDOOR_MIN_FRACTION",
    "MIN_REACHABLE_M3",
    "NAME_PATTERN",
    "PLATEAU_RANGE",
    "PLATEAU_S_PER_M3",
    "PREFERRED_HEIGHT",
    "START_REACH",
    "STOREY_MIN_FRACTION",
    "STOREY_MIN_GAP",
    "SUPPORTED_EXTENSIONS",
    "TOP_MARGIN",
    "ImportLimits",
    "MeshImportError",
    "UpAxis",
    "import_mesh",
]

UpAxis = Literal["x", "y", "z", "-x", "-y", "-z"]

NAME_PATTERN = re.compile(r"[a-z0-9-]{1,40}")

HORIZONTAL_MARGIN = 0.5  # metres beyond one voxel on each horizontal side
TOP_MARGIN = 0.5  # metres above the mesh
PLATEAU_S_PER_M3 = 0.8
PLATEAU_RANGE = (300.0, 1800.0)

# Rotations taking each ``up`` axis to +z (proper rotations, det +1).
_UP_ROTATIONS: dict[str, FloatArray] = {
    "z": np.eye(3),
    "-z": np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]),
    "y": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]),
    "-y": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]),
    "x": np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]]),
    "-x": np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]),
}


class ImportLimits(BaseModel):
    """Resource limits on an imported mesh."""

    model_config = ConfigDict(frozen=True)

    max_file_bytes: int = Field(default=200 * 1024 * 1024, gt=0)
    max_faces: int = Field(default=5_000_000, gt=0)
    max_extent_m: float = Field(default=300.0, gt=0.0)


def import_mesh(
    path: Path,
    name: str,
    *,
    scale: float = 1.0,
    up: UpAxis = "z",
    voxel_size: float = 0.1,
    start: StartPose | None = None,
    plateau_s: float | None = None,
    limits: ImportLimits = ImportLimits(),  # noqa: B008 - frozen, hence safe to share
) -> Area:
    """An area from a mesh file, in metres, z up (see the module docstring for each step).

    Args:
        path: the mesh file; the format comes from its extension.
        name: the area's name: lower case letters, digits and hyphens, 1 to 40 characters.
        scale: metres per file unit, applied after COLLADA's own unit.
        up: the file's up axis, rotated onto +z.
        voxel_size: occupancy voxel edge in metres.
        start: start pose; chosen automatically when None.
        plateau_s: exploration plateau in simulated seconds; when None,
            ``clamp(0.8 × free volume of the start's component in m³, 300, 1800)``.
        limits: file size, face count and extent limits.

    Raises:
        MeshImportError: for an invalid name, scale, up axis or voxel size, an unsupported, too
            large, unreadable or empty file, non-finite coordinates, too many faces, too large an
            extent, or no free space with enough clearance for a start.
    """
    _check_parameters(name, scale, up, voxel_size)
    path = Path(path)
    suffix = _check_file(path, limits)
    vertices, faces, unit = _read_mesh(path, suffix, limits)
    vertices = (vertices * (unit * scale)) @ _UP_ROTATIONS[up].T
    bounds_min, bounds_max = _grid_bounds(vertices, voxel_size, limits)

    area = Area(
        name=name,
        vertices=np.ascontiguousarray(vertices, dtype=np.float64),
        triangles=np.ascontiguousarray(faces, dtype=np.int32),
        bounds_min=bounds_min,
        bounds_max=bounds_max,
        start=StartPose(position=bounds_min.copy(), yaw=0.0),
        plateau_s=PLATEAU_RANGE[0],
        voxel_size=float(voxel_size),
        info=AreaInfo(title=name, rooms=None, levels=1, complexity="imported", indoor=False),
    )
    auto = choose_start(area)
    if start is None:
        start = auto.start
    if plateau_s is None:
        plateau_s = float(np.clip(PLATEAU_S_PER_M3 * auto.volume_m3, *PLATEAU_RANGE))
    return Area(
        name=name,
        vertices=area.vertices,
        triangles=area.triangles,
        bounds_min=bounds_min,
        bounds_max=bounds_max,
        start=start,
        plateau_s=float(plateau_s),
        voxel_size=float(voxel_size),
        info=AreaInfo(
            title=name, rooms=None, levels=auto.levels, complexity="imported", indoor=auto.indoor
        ),
    )


def _check_parameters(name: str, scale: float, up: str, voxel_size: float) -> None:
    """Step 1, the request's values: the area name, the scale, the up axis, the voxel size."""
    if not isinstance(name, str) or NAME_PATTERN.fullmatch(name) is None:
        raise MeshImportError(
            f"invalid area name {name!r}: use 1 to 40 lower case letters, digits or hyphens"
        )
    if not np.isfinite(scale) or scale <= 0.0:
        raise MeshImportError(f"scale must be a positive number, got {scale}")
    if up not in _UP_ROTATIONS:
        raise MeshImportError(f"unknown up axis {up!r}; use one of {', '.join(_UP_ROTATIONS)}")
    if not np.isfinite(voxel_size) or voxel_size <= 0.0:
        raise MeshImportError(f"voxel size must be a positive number, got {voxel_size}")


def _check_file(path: Path, limits: ImportLimits) -> str:
    """Step 1, the file: its extension (returned, lower case) and its size."""
    suffix = path.suffix.lower()
    if suffix not in SUPPORTED_EXTENSIONS:
        raise MeshImportError(
            f"unsupported file extension {path.suffix or '(none)'!r}; "
            f"supported: {', '.join(SUPPORTED_EXTENSIONS)}"
        )
    try:
        size = path.stat().st_size
    except OSError as exc:
        raise MeshImportError(f"cannot read mesh file {path.name}: {exc}") from exc
    if size > limits.max_file_bytes:
        raise MeshImportError(
            f"mesh file too large: {size} bytes, the limit is {limits.max_file_bytes} bytes"
        )
    return suffix


def _read_mesh(path: Path, suffix: str,
               limits: ImportLimits) -> tuple[FloatArray, IntArray, float]:
    """Steps 2 to 4 but the scaling: the cleaned vertices and triangles as stored, and metres
    per file unit."""
    vertices, faces, unit = load_mesh_file(path, suffix)
    if len(faces) == 0:
        raise MeshImportError(f"mesh file {path.name} holds no triangles")
    if len(faces) > limits.max_faces:
        raise MeshImportError(
            f"too many faces: {len(faces)}, the limit is {limits.max_faces}"
        )
    if not np.all(np.isfinite(vertices[np.unique(faces)])):
        raise MeshImportError(
            f"mesh file {path.name} has non-finite (NaN or infinite) vertex coordinates"
        )
    vertices, faces = drop_degenerate_faces(vertices, faces)
    if len(faces) == 0:
        raise MeshImportError(
            f"mesh file {path.name} is empty after dropping degenerate (zero-area) faces"
        )
    return vertices, faces, unit


def _grid_bounds(vertices: FloatArray, voxel_size: float,
                 limits: ImportLimits) -> tuple[FloatArray, FloatArray]:
    """Step 5: the grid's lower and upper corners around ``vertices`` (metres, z up), after
    checking the mesh's extent against ``limits``."""
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    extent = hi - lo
    if float(extent.max()) > limits.max_extent_m:
        raise MeshImportError(
            f"mesh extent too large: {np.round(extent, 2).tolist()} m, "
            f"the limit is {limits.max_extent_m} m on each axis"
        )
    margin = np.array([voxel_size + HORIZONTAL_MARGIN] * 2 + [0.0])
    top = np.array([voxel_size + HORIZONTAL_MARGIN] * 2 + [TOP_MARGIN])
    bounds_min = np.floor((lo - margin) / voxel_size + 1e-9) * voxel_size
    bounds_max = bounds_min + np.ceil((hi + top - bounds_min) / voxel_size - 1e-9) * voxel_size
    return bounds_min, bounds_max
