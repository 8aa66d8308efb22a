"""Reading a user's mesh file (the first steps of `areas.importer.import_mesh`).

The file signature is checked cheaply first, so that garbage bytes are reported as unreadable
rather than as an empty mesh; trimesh then loads it (scenes flattened with their node transforms
applied). COLLADA's ``<asset><unit meter="...">`` is read from the XML, since trimesh keeps the
file's units. Every problem is a `MeshImportError` naming the file.
"""

from __future__ import annotations

import contextlib
import json
import logging
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import trimesh

from areas.mesh import FloatArray, IntArray

SUPPORTED_EXTENSIONS = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf", ".dae")


class MeshImportError(ValueError):
    """A mesh file that cannot become an area; the message names the problem and the value."""


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


def load_mesh_file(path: Path, suffix: str) -> tuple[FloatArray, IntArray, float]:
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


def drop_degenerate_faces(vertices: FloatArray,
                          faces: IntArray) -> tuple[FloatArray, IntArray]:
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
