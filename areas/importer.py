"""Import a user's triangle mesh (OBJ, PLY, STL, OFF, GLB/GLTF, COLLADA) as an `Area`.

Pipeline (`import_mesh`):

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
6. Start pose (when not given): the blocked voxels of the ground truth (centres within half a voxel
   of the mesh) split the grid into 6-connected free components. The largest component that does
   not touch the outer faces of the grid (an inside) is chosen if it holds at least
   `INDOOR_MIN_FRACTION` of the largest component's volume and room for the vehicle; otherwise the
   largest component with room for the vehicle. In it the start is the voxel centre with the largest
   distance to the mesh and to the grid's faces, among those 1-2 m above the floor below them if any
   has at least `MIN_CLEARANCE`, else among all. Yaw 0.
7. Plateau time (when not given): ``clamp(0.8 s/m³ × volume of the chosen component, 300, 1800)``
   seconds, the free volume a perfect exploration could fly through.
"""

from __future__ import annotations

import contextlib
import json
import logging
import re
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import numpy.typing as npt
import open3d as o3d
import trimesh
from pydantic import BaseModel, ConfigDict, Field
from scipy import ndimage

from areas.area import Area, AreaInfo, StartPose
from areas.ground_truth import blocked_voxels

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]
UpAxis = Literal["x", "y", "z", "-x", "-y", "-z"]

SUPPORTED_EXTENSIONS = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf", ".dae")
NAME_PATTERN = re.compile(r"[a-z0-9-]{1,40}")

HORIZONTAL_MARGIN = 0.5  # metres beyond one voxel on each horizontal side
TOP_MARGIN = 0.5  # metres above the mesh
MIN_CLEARANCE = 0.5  # metres from the start to the mesh and to the grid's faces
PREFERRED_HEIGHT = (1.0, 2.0)  # metres above the floor below the start
INDOOR_MIN_FRACTION = 0.25  # of the largest component's volume, for an inside to be chosen
PLATEAU_S_PER_M3 = 0.8
EXACT_CANDIDATES = 20_000  # voxels whose exact clearance is computed
PLATEAU_RANGE = (300.0, 1800.0)
STOREY_MIN_GAP = 2.0  # metres between two floor heights counted as distinct levels
STOREY_MIN_FRACTION = 0.25  # of the largest floor area, for a floor height to count as a level

# Rotations taking each ``up`` axis to +z (proper rotations, det +1).
_UP_ROTATIONS: dict[str, FloatArray] = {
    "z": np.eye(3),
    "-z": np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]),
    "y": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]),
    "-y": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]),
    "x": np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]]),
    "-x": np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]),
}


class MeshImportError(ValueError):
    """A mesh file that cannot become an area; the message names the problem and the value."""


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
    path = Path(path)
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

    vertices, faces, unit = _load(path, suffix)
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
    vertices, faces = _clean(vertices, faces)
    if len(faces) == 0:
        raise MeshImportError(
            f"mesh file {path.name} is empty after dropping degenerate (zero-area) faces"
        )
    vertices = (vertices * (unit * scale)) @ _UP_ROTATIONS[up].T
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
    auto = _choose_start(area)
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


@contextlib.contextmanager
def _quiet_trimesh() -> Iterator[None]:
    """Silence trimesh's log (it logs a traceback per missing texture)."""
    logger = logging.getLogger("trimesh")
    level = logger.level
    logger.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        logger.setLevel(level)


def _check_signature(path: Path, suffix: str) -> None:
    """Raise MeshImportError when the file cannot be of its format (cheap header checks)."""
    unreadable = f"unreadable or corrupt {suffix[1:].upper()} file {path.name}"
    with path.open("rb") as f:
        head = f.read(1024)
    size = path.stat().st_size
    if suffix == ".stl":
        ascii_ok = head.lstrip().lower().startswith(b"solid") and b"\0" not in head
        binary_ok = size >= 84 and size == 84 + 50 * int.from_bytes(head[80:84], "little")
        if not (ascii_ok or binary_ok):
            raise MeshImportError(f"{unreadable}: neither ASCII nor binary STL")
    elif suffix == ".glb":
        if not head.startswith(b"glTF"):
            raise MeshImportError(f"{unreadable}: no glTF binary header")
    elif suffix == ".ply":
        if not head.startswith(b"ply"):
            raise MeshImportError(f"{unreadable}: no PLY header")
    elif suffix in (".obj", ".off", ".gltf", ".dae"):
        try:
            text = path.read_bytes().decode("utf-8")
        except UnicodeDecodeError as exc:
            raise MeshImportError(f"{unreadable}: not UTF-8 text ({exc.reason})") from exc
        if "\0" in text:
            raise MeshImportError(f"{unreadable}: binary data in a text format")
        if suffix == ".off" and "OFF" not in text.lstrip()[:8]:
            raise MeshImportError(f"{unreadable}: no OFF header")
        if suffix == ".gltf":
            try:
                json.loads(text)
            except ValueError as exc:
                raise MeshImportError(f"{unreadable}: invalid JSON ({exc})") from exc


def _collada_unit(path: Path) -> float:
    """Metres per unit declared by a COLLADA file's ``<asset><unit meter=...>`` (1 if absent)."""
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError) as exc:
        raise MeshImportError(f"unreadable or corrupt DAE file {path.name}: {exc}") from exc
    for element in root.iter():
        if element.tag.rsplit("}", 1)[-1] == "unit" and "meter" in element.attrib:
            try:
                unit = float(element.attrib["meter"])
            except ValueError as exc:
                raise MeshImportError(
                    f"invalid COLLADA unit meter={element.attrib['meter']!r} in {path.name}"
                ) from exc
            if not np.isfinite(unit) or unit <= 0.0:
                raise MeshImportError(f"invalid COLLADA unit meter={unit} in {path.name}")
            return unit
    return 1.0


def _load(path: Path, suffix: str) -> tuple[FloatArray, IntArray, float]:
    """Vertices, triangles and metres per unit of a mesh file, as stored (no cleaning)."""
    _check_signature(path, suffix)
    unit = _collada_unit(path) if suffix == ".dae" else 1.0
    try:
        with _quiet_trimesh():
            loaded = trimesh.load(path, force="mesh", process=False)
    except MeshImportError:
        raise
    except Exception as exc:  # any loader failure means a bad file
        raise MeshImportError(
            f"unreadable or corrupt {suffix[1:].upper()} file {path.name}: {exc}"
        ) from exc
    if not isinstance(loaded, trimesh.Trimesh):
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64), unit
    vertices = np.asarray(loaded.vertices, dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(loaded.faces, dtype=np.int64).reshape(-1, 3)
    if len(faces) and (faces.min() < 0 or faces.max() >= len(vertices)):
        raise MeshImportError(f"unreadable or corrupt file {path.name}: face index out of range")
    return vertices, faces, unit


def _clean(vertices: FloatArray, faces: IntArray) -> tuple[FloatArray, IntArray]:
    """Drop faces with repeated indices or zero area, then vertices no face uses."""
    repeated = (
        (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 0] == faces[:, 2])
    )
    corners = vertices[faces]
    twice_area = np.linalg.norm(
        np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1
    )
    faces = faces[~repeated & (twice_area > 0.0)]
    used, compact = np.unique(faces, return_inverse=True)
    return vertices[used], compact.reshape(-1, 3).astype(np.int64)


@dataclass(frozen=True)
class _AutoStart:
    """What the free-space analysis found: the start and the statistics of its component."""

    start: StartPose
    volume_m3: float
    levels: int
    indoor: bool


def _choose_start(area: Area) -> _AutoStart:
    """The automatic start pose and the statistics of its free component (module docstring)."""
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
    return _AutoStart(
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
