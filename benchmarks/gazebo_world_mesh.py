"""One triangle mesh from a Gazebo world made of static model meshes (geometry only).

    .venv/bin/python benchmarks/gazebo_world_mesh.py SOURCE WORLD OUT.ply \
        [--uncomment MODEL ...] [--drop MODEL ...] [--collision URI ...]

SOURCE is a checkout of a world repository laid out as the AWS RoboMaker worlds are
(``worlds/*.world`` and ``models/<name>/model.sdf`` with COLLADA meshes); WORLD is the world
file's path inside it. Every ``<model>`` of the world that includes a model of the repository is
placed with its pose; each model's visual meshes are placed with the model's, link's and
visual's poses and the mesh's scale, in metres (COLLADA's ``<unit meter>`` applied). Spheres
become icospheres; textures and materials are dropped. The result is written as binary PLY with
duplicate vertices merged.

``--uncomment MODEL`` also places a world model that the world file has inside an XML comment
(the AWS worlds comment their ceilings out to ease viewing from above); ``--drop MODEL`` leaves
a world model out (the bookstore world has a book 343 km above the floor). ``--collision URI``
uses a model's collision mesh instead of its visual one: for small decoration whose visual mesh
holds many triangles, and for a visual mesh absent from the checkout (then chosen
automatically, with a note).

This script rebuilds the files under ``tests/data/meshes``; the tests only read those files.
"""

from __future__ import annotations

import argparse
import logging
import re
import sys
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
import trimesh

Matrix = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Placed:
    """One world model: its name, the model URI it includes, and its pose in the world."""

    name: str
    uri: str
    pose: Matrix


def pose_matrix(element: ET.Element | None) -> Matrix:
    """4x4 transform of an SDF ``<pose>x y z roll pitch yaw</pose>`` (identity when absent)."""
    matrix = np.eye(4)
    text = "" if element is None else (element.text or "").strip()
    if not text:
        return matrix
    x, y, z, roll, pitch, yaw = (float(v) for v in text.split())
    # SDF's fixed-axis roll, pitch, yaw: R = Rz(yaw) Ry(pitch) Rx(roll).
    matrix[:3, :3] = trimesh.transformations.euler_matrix(roll, pitch, yaw, "sxyz")[:3, :3]
    matrix[:3, 3] = (x, y, z)
    return matrix


def world_models(world: Path, uncomment: set[str]) -> list[Placed]:
    """The world's models that include another model, plus the commented-out ones asked for."""
    text = world.read_text()
    found: list[Placed] = []
    root = ET.fromstring(text).find("world")
    if root is None:
        raise SystemExit(f"{world}: no <world> element")
    elements = list(root.findall("model"))
    for comment in re.findall(r"<!--(.*?)-->", text, flags=re.DOTALL):
        if "<model" not in comment:
            continue
        try:
            wrapped = ET.fromstring(f"<c>{comment}</c>")
        except ET.ParseError:
            continue  # a comment that is not XML
        elements += [m for m in wrapped.findall("model") if m.get("name") in uncomment]
    for model in elements:
        uri = model.find("include/uri")
        text = "" if uri is None else (uri.text or "").strip()
        if text:
            found.append(Placed(str(model.get("name")), text, pose_matrix(model.find("pose"))))
    missing = uncomment - {p.name for p in found}
    if missing:
        raise SystemExit(f"{world}: no commented-out model named {', '.join(sorted(missing))}")
    return found


def resolve(source: Path, uri: str) -> Path:
    """The file of a ``model://`` or ``file://`` URI inside the checkout (case-insensitive)."""
    if uri.startswith("model://"):
        path = source / "models" / uri.removeprefix("model://")
    elif uri.startswith("file://"):
        path = source / uri.removeprefix("file://")
    else:
        raise SystemExit(f"unsupported URI {uri}")
    if path.exists() or not path.parent.is_dir():
        return path
    matches = [p for p in path.parent.iterdir() if p.name.lower() == path.name.lower()]
    return matches[0] if matches else path


def collada_mesh(path: Path) -> trimesh.Trimesh:
    """A COLLADA file's triangles in metres (trimesh keeps the file's own unit)."""
    unit = re.search(rb'<unit[^>]*meter="([^"]+)"', path.read_bytes()[:4096])
    mesh = trimesh.load(path, force="mesh", process=False)
    if not isinstance(mesh, trimesh.Trimesh):
        raise SystemExit(f"{path}: no triangles")
    mesh.apply_scale(float(unit.group(1)) if unit else 1.0)
    return mesh


def geometry_mesh(source: Path, element: ET.Element, use_collision: bool,
                  uri_note: list[str]) -> trimesh.Trimesh | None:
    """The triangles of one ``<visual>``'s geometry, in the visual's frame."""
    sphere = element.find("geometry/sphere/radius")
    if sphere is not None:
        return trimesh.creation.icosphere(subdivisions=2, radius=float(sphere.text or 0))
    uri = element.find("geometry/mesh/uri")
    if uri is None:
        return None
    path = resolve(source, (uri.text or "").strip())
    if use_collision or not path.exists():
        collision = path.with_name(re.sub(r"_visual(\.\w+)$", r"_collision\1", path.name,
                                          flags=re.IGNORECASE))
        if not path.exists():
            uri_note.append(f"visual mesh {path.name} absent: its collision mesh is used")
        path = collision
    mesh = collada_mesh(path)
    scale = element.find("geometry/mesh/scale")
    if scale is not None and scale.text:
        mesh.apply_transform(np.diag([*(float(v) for v in scale.text.split()), 1.0]))
    return mesh


def model_meshes(source: Path, placed: Placed, collision: set[str],
                 notes: list[str]) -> list[trimesh.Trimesh]:
    """The visual meshes of one placed model, in world coordinates."""
    sdf = resolve(source, placed.uri) / "model.sdf"
    model = ET.parse(sdf).getroot().find("model")
    if model is None:
        raise SystemExit(f"{sdf}: no <model> element")
    base = placed.pose @ pose_matrix(model.find("pose"))
    meshes = []
    for link in model.findall("link"):
        at_link = base @ pose_matrix(link.find("pose"))
        for visual in link.findall("visual"):
            mesh = geometry_mesh(source, visual, placed.uri in collision, notes)
            if mesh is not None:
                mesh.apply_transform(at_link @ pose_matrix(visual.find("pose")))
                meshes.append(mesh)
    return meshes


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("source", type=Path, help="checkout of the world repository")
    parser.add_argument("world", help="world file inside the checkout")
    parser.add_argument("out", type=Path, help="PLY file to write")
    parser.add_argument("--uncomment", nargs="*", default=[], metavar="MODEL")
    parser.add_argument("--drop", nargs="*", default=[], metavar="MODEL")
    parser.add_argument("--collision", nargs="*", default=[], metavar="URI")
    args = parser.parse_args(argv)
    logging.getLogger("trimesh").setLevel(logging.CRITICAL)  # one traceback per texture

    notes: list[str] = []
    meshes: list[trimesh.Trimesh] = []
    for placed in world_models(args.source / args.world, set(args.uncomment)):
        if placed.name in args.drop:
            continue
        meshes += model_meshes(args.source, placed, set(args.collision), notes)
    joined = trimesh.util.concatenate(meshes)
    assert isinstance(joined, trimesh.Trimesh)
    # A fresh mesh, so that only positions and triangles are written (no normals, no colours).
    out = trimesh.Trimesh(np.asarray(joined.vertices, dtype=np.float32).astype(np.float64),
                          joined.faces, process=False)
    out.merge_vertices()
    out.export(args.out, file_type="ply", encoding="binary")
    for note in sorted(set(notes)):
        print(note)
    extent = np.round(np.ptp(out.vertices, axis=0), 2).tolist()
    print(f"{args.out}: {len(meshes)} meshes, {len(out.faces)} faces, {len(out.vertices)} "
          f"vertices, extent {extent} m, {args.out.stat().st_size} bytes")
    return 0


if __name__ == "__main__":
    sys.exit(main())
