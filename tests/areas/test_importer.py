"""Mesh import: real COLLADA buildings, synthetic boxes in every format, and each invalid case.

The real meshes used here, from ``tests/data/meshes``, are the Gazebo model database models
``cafe`` and ``apartment`` by Nate Koenig, licensed under Creative Commons Attribution 3.0
Unported (see the README.md beside them).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import open3d as o3d
import pytest
import trimesh

from areas.area import Area, StartPose
from areas.auto_start import covered_fraction
from areas.ground_truth import compute_ground_truth
from areas.importer import ImportLimits, MeshImportError, import_mesh

MESHES = Path(__file__).resolve().parents[1] / "data" / "meshes"


@pytest.fixture(autouse=True)
def _no_cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("FLYBO_CACHE_DIR", str(tmp_path / "cache"))


@pytest.fixture(scope="module")
def cafe() -> Area:
    return import_mesh(MESHES / "cafe.dae", "cafe")


def _clearance(area: Area, point: np.ndarray) -> float:
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor.from_numpy(area.vertices.astype(np.float32)),
        o3d.core.Tensor.from_numpy(area.triangles.astype(np.uint32)),
    )
    query = o3d.core.Tensor.from_numpy(point[None, :].astype(np.float32))
    return float(scene.compute_distance(query).numpy()[0])


def _check_real(area: Area, expected: tuple[float, float, float]) -> None:
    extent = np.ptp(area.vertices, axis=0)
    np.testing.assert_allclose(extent, expected, rtol=0.15)
    # The explorable box holds the mesh, starts at its floor and lies on whole voxels.
    assert np.all(area.bounds_min <= area.vertices.min(axis=0))
    assert np.all(area.bounds_max >= area.vertices.max(axis=0))
    assert area.bounds_min[2] == pytest.approx(
        np.floor(area.vertices[:, 2].min() / area.voxel_size) * area.voxel_size
    )
    assert _clearance(area, area.start.position) >= 0.45
    assert np.all(area.start.position > area.bounds_min + 0.5)
    assert np.all(area.start.position < area.bounds_max - 0.5)
    assert 300.0 <= area.plateau_s <= 1800.0
    assert area.info.complexity == "imported"
    assert compute_ground_truth(area).observable_volume_m3 > 0.0


@pytest.mark.slow  # the COLLADA parse and ground truth of a real building
def test_cafe_imports_in_metres(cafe: Area) -> None:
    _check_real(cafe, (10.0, 24.0, 2.9))
    assert cafe.info.levels == 1


@pytest.mark.slow  # the COLLADA parse and ground truth of a real building
def test_apartment_imports_in_metres() -> None:
    area = import_mesh(MESHES / "apartment.dae", "apartment")
    _check_real(area, (20.0, 22.0, 15.0))
    assert area.info.levels >= 2


@pytest.mark.slow
def test_short_flight_in_the_cafe(cafe: Area) -> None:
    from planners.registry import make
    from sim.config import preset
    from sim.episode import run_episode

    result = run_episode(
        cafe, compute_ground_truth(cafe), make("classic"), preset("exact"), seed=0, seconds=20
    )
    assert result.status == "succeeded"
    assert result.collisions == 0


def _box(extents: tuple[float, float, float]) -> trimesh.Trimesh:
    return trimesh.creation.box(extents=extents)


@pytest.mark.parametrize("ext", ["obj", "ply", "stl", "off", "glb"])
def test_box_in_each_format(tmp_path: Path, ext: str) -> None:
    path = tmp_path / f"box.{ext}"
    _box((2.0, 3.0, 4.0)).export(path)
    area = import_mesh(path, "box")
    np.testing.assert_allclose(np.ptp(area.vertices, axis=0), [2.0, 3.0, 4.0], atol=1e-6)
    # The inside of the closed box is chosen: 1 m from the side walls at x = +-1.
    assert area.info.indoor
    assert abs(area.start.position[0]) == pytest.approx(0.05)  # a voxel centre nearest x = 0
    assert _clearance(area, area.start.position) >= 0.45
    assert area.info.levels == 1
    assert area.plateau_s == 300.0  # about 24 m³ of free space: the lower clamp
    np.testing.assert_allclose(area.bounds_min, [-1.6, -2.1, -2.0], atol=1e-9)
    np.testing.assert_allclose(area.bounds_max, [1.6, 2.1, 2.5], atol=1e-9)


def test_scale_and_up_axis(tmp_path: Path) -> None:
    path = tmp_path / "box.obj"
    _box((200.0, 300.0, 400.0)).export(path)
    scaled = import_mesh(path, "box", scale=0.01)
    np.testing.assert_allclose(np.ptp(scaled.vertices, axis=0), [2.0, 3.0, 4.0], atol=1e-9)

    corner = tmp_path / "corner.obj"
    # A box from the origin to (2, 3, 4): with +y up, (x, y, z) becomes (x, -z, y).
    trimesh.creation.box(
        extents=(2.0, 3.0, 4.0), transform=trimesh.transformations.translation_matrix([1, 1.5, 2])
    ).export(corner)
    area = import_mesh(corner, "corner", up="y")
    np.testing.assert_allclose(area.vertices.min(axis=0), [0.0, -4.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(area.vertices.max(axis=0), [2.0, 0.0, 3.0], atol=1e-9)
    down = import_mesh(corner, "corner", up="-z")
    np.testing.assert_allclose(down.vertices.min(axis=0), [0.0, -3.0, -4.0], atol=1e-9)
    side = import_mesh(corner, "corner", up="x")
    np.testing.assert_allclose(np.ptp(side.vertices, axis=0), [4.0, 3.0, 2.0], atol=1e-9)


def test_given_start_and_plateau_are_kept(tmp_path: Path) -> None:
    path = tmp_path / "box.stl"
    _box((2.0, 3.0, 4.0)).export(path)
    start = StartPose(position=np.array([0.1, 0.2, 0.3]), yaw=1.0)
    area = import_mesh(path, "box", start=start, plateau_s=42.0)
    assert area.start is start
    assert area.plateau_s == 42.0


def _write(path: Path, data: str | bytes) -> Path:
    if isinstance(data, str):
        path.write_text(data)
    else:
        path.write_bytes(data)
    return path


GARBAGE = bytes(np.random.default_rng(0).integers(0, 256, 3000, dtype=np.uint8))


def test_unsupported_extension(tmp_path: Path) -> None:
    with pytest.raises(MeshImportError, match=r"unsupported file extension '\.txt'.*\.obj"):
        import_mesh(_write(tmp_path / "mesh.txt", "v 0 0 0\n"), "m")


@pytest.mark.parametrize("ext", ["stl", "obj"])
def test_garbage_bytes(tmp_path: Path, ext: str) -> None:
    with pytest.raises(MeshImportError, match=rf"unreadable or corrupt {ext.upper()} file"):
        import_mesh(_write(tmp_path / f"garbage.{ext}", GARBAGE), "m")


def test_no_triangles(tmp_path: Path) -> None:
    with pytest.raises(MeshImportError, match="holds no triangles"):
        import_mesh(_write(tmp_path / "points.obj", "v 0 0 0\nv 1 0 0\n"), "m")


def test_nan_vertex(tmp_path: Path) -> None:
    obj = "v 0 0 0\nv 1 0 0\nv 0 nan 0\nf 1 2 3\n"
    with pytest.raises(MeshImportError, match="non-finite"):
        import_mesh(_write(tmp_path / "nan.obj", obj), "m")


def test_all_degenerate_faces(tmp_path: Path) -> None:
    obj = "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\nf 1 1 2\n"
    with pytest.raises(MeshImportError, match="empty after dropping degenerate"):
        import_mesh(_write(tmp_path / "flat.obj", obj), "m")


def test_degenerate_faces_and_unused_vertices_are_dropped(tmp_path: Path) -> None:
    box = _box((2.0, 3.0, 4.0))
    extra = "v 9 9 9\nv 0 0 0\nv 1 0 0\nv 2 0 0\nf 10 11 12\nf 10 10 11\n"
    path = tmp_path / "box.obj"
    box.export(path)
    path.write_text(path.read_text() + extra)
    area = import_mesh(path, "box")
    assert len(area.triangles) == 12
    assert len(area.vertices) == 8


def test_too_many_faces(tmp_path: Path) -> None:
    path = tmp_path / "box.obj"
    _box((2.0, 3.0, 4.0)).export(path)
    with pytest.raises(MeshImportError, match="too many faces: 12, the limit is 10"):
        import_mesh(path, "m", limits=ImportLimits(max_faces=10))


def test_extent_too_large(tmp_path: Path) -> None:
    path = tmp_path / "box.obj"
    _box((2.0, 3.0, 4.0)).export(path)
    with pytest.raises(MeshImportError, match=r"extent too large: \[2000\.0, 3000\.0, 4000\.0\]"):
        import_mesh(path, "m", scale=1000.0, limits=ImportLimits(max_extent_m=300.0))


def test_file_too_large(tmp_path: Path) -> None:
    path = tmp_path / "box.obj"
    _box((2.0, 3.0, 4.0)).export(path)
    with pytest.raises(MeshImportError, match=r"file too large: \d+ bytes, the limit is 10 bytes"):
        import_mesh(path, "m", limits=ImportLimits(max_file_bytes=10))


@pytest.mark.parametrize("scale", [0.0, -1.0, float("nan")])
def test_non_positive_scale(tmp_path: Path, scale: float) -> None:
    path = tmp_path / "box.obj"
    _box((2.0, 3.0, 4.0)).export(path)
    with pytest.raises(MeshImportError, match="scale must be a positive number"):
        import_mesh(path, "m", scale=scale)


@pytest.mark.parametrize("name", ["", "Cafe", "my cafe", "a_b", "x" * 41])
def test_bad_name(tmp_path: Path, name: str) -> None:
    path = tmp_path / "box.obj"
    _box((2.0, 3.0, 4.0)).export(path)
    with pytest.raises(MeshImportError, match="invalid area name"):
        import_mesh(path, name)


def test_no_room_for_a_start(tmp_path: Path) -> None:
    path = tmp_path / "small.obj"
    _box((0.5, 0.5, 0.5)).export(path)
    with pytest.raises(MeshImportError, match=r"no free space has room for the vehicle"):
        import_mesh(path, "small")


def test_a_mesh_with_no_gap_the_vehicle_fits_is_refused_saying_why(tmp_path: Path) -> None:
    """A closed crawl space 0.8 m high: 28 m³ of free space, none of it 0.9 m across."""
    path = tmp_path / "crawl.obj"
    _box((6.0, 6.0, 0.8)).export(path)
    with pytest.raises(MeshImportError, match=r"no free space has room for the vehicle \(0\.45 m"):
        import_mesh(path, "crawl")


def test_the_start_sees_structure_and_the_vehicle_can_fly_from_it(tmp_path: Path) -> None:
    """A closed 30 x 30 x 12 m hall: the start is within camera reach of a surface, 1-2 m above
    the floor, and traversable by the planners' rule."""
    from areas.ground_truth import blocked_voxels
    from areas.observability import ViewModel, traversable

    path = tmp_path / "hall.obj"
    _box((30.0, 30.0, 12.0)).export(path)
    area = import_mesh(path, "hall", voxel_size=0.2)
    assert _clearance(area, area.start.position) <= 4.0
    # 1-2 m above the top of the floor's blocked voxels, at most a voxel above the floor itself.
    assert 1.0 <= area.start.position[2] - (-6.0) <= 2.0 + area.voxel_size
    ijk = tuple(((area.start.position - area.bounds_min) / area.voxel_size).astype(int))
    walkable = traversable(blocked_voxels(area), area.voxel_size, ViewModel().safety_radius_m)
    assert walkable[ijk]


def test_an_area_is_indoor_when_most_of_the_reachable_space_is_under_a_surface() -> None:
    blocked = np.zeros((10, 10, 6), dtype=bool)
    space = np.zeros_like(blocked)
    space[1:9, 1:9, 1:4] = True
    assert covered_fraction(blocked, space) == 0.0  # open sky
    blocked[1:9, 1:5, 5] = True  # a roof over half of it
    assert covered_fraction(blocked, space) == pytest.approx(0.5)
    blocked[:, :, 5] = True
    assert covered_fraction(blocked, space) == 1.0
    blocked[1:9, 1:9, 2] = True  # a deck inside: the space above it is under the roof still
    assert covered_fraction(blocked, space & ~blocked) == 1.0
    assert covered_fraction(blocked, np.zeros_like(blocked)) == 0.0


def test_a_roofed_room_with_an_open_door_is_indoor_and_a_roofless_one_outdoor(
        tmp_path: Path) -> None:
    floor = trimesh.creation.box(extents=(6.0, 6.0, 0.2))
    walls = []
    for x, y, ex, ey in ((3.0, 0.0, 0.2, 6.0), (-3.0, 0.0, 0.2, 6.0), (0.0, -3.0, 6.0, 0.2)):
        wall = trimesh.creation.box(extents=(ex, ey, 3.0))
        wall.apply_translation((x, y, 1.5))
        walls.append(wall)
    for x in (-2.0, 2.0):  # the fourth wall with a 2 m door between x = -1 and 1
        wall = trimesh.creation.box(extents=(2.0, 0.2, 3.0))
        wall.apply_translation((x, 3.0, 1.5))
        walls.append(wall)
    roof = trimesh.creation.box(extents=(6.2, 6.2, 0.2))
    roof.apply_translation((0.0, 0.0, 3.1))
    for name, parts in (("roofed", [floor, *walls, roof]), ("roofless", [floor, *walls])):
        path = tmp_path / f"{name}.ply"
        trimesh.util.concatenate(parts).export(path)
        area = import_mesh(path, name)
        assert area.info.indoor == (name == "roofed"), name
