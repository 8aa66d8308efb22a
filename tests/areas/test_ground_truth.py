"""Ground truth on hand-checkable boxes and on MAZE, and its disk cache."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import numpy.typing as npt
import open3d as o3d
import pytest
import trimesh

from areas import ground_truth
from areas.area import Area, AreaInfo, StartPose
from areas.ground_truth import (
    DEFAULT_SAMPLE_SPACING,
    compute_ground_truth,
    ground_truth_path,
    load_ground_truth,
)
from areas.maze import CELL_SIZE, CELLS, HEIGHT, WALL_THICKNESS, build_maze, maze_passages

VOXEL = 0.1


def _box(lo: list[float], hi: list[float], inward: bool = True) -> trimesh.Trimesh:
    """Closed axis-aligned box from ``lo`` to ``hi``; normals inward unless told otherwise."""
    lo_a, hi_a = np.array(lo), np.array(hi)
    box = trimesh.creation.box(
        extents=hi_a - lo_a, transform=trimesh.transformations.translation_matrix((lo_a + hi_a) / 2)
    )
    if inward:
        box.invert()
    return box


def _area(
    meshes: list[trimesh.Trimesh], lo: list[float], hi: list[float], start: list[float]
) -> Area:
    offsets = np.cumsum([0] + [len(m.vertices) for m in meshes])
    return Area(
        name="test",
        vertices=np.concatenate([np.asarray(m.vertices, dtype=np.float64) for m in meshes]),
        triangles=np.concatenate(
            [np.asarray(m.faces) + off for m, off in zip(meshes, offsets, strict=False)]
        ).astype(np.int32),
        bounds_min=np.array(lo, dtype=np.float64),
        bounds_max=np.array(hi, dtype=np.float64),
        start=StartPose(position=np.array(start, dtype=np.float64), yaw=0.0),
        plateau_s=10.0,
        voxel_size=VOXEL,
        info=AreaInfo(title="TEST", rooms=1, levels=1, complexity="low", indoor=True),
    )


def _distance_to(mesh: trimesh.Trimesh, points: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor.from_numpy(np.asarray(mesh.vertices, dtype=np.float32)),
        o3d.core.Tensor.from_numpy(np.asarray(mesh.faces, dtype=np.uint32)),
    )
    return scene.compute_distance(o3d.core.Tensor.from_numpy(points)).numpy()


def test_aligned_box_counts_every_inside_voxel() -> None:
    # A 4 x 3 x 2.5 m box whose faces lie on voxel faces, in a grid with 0.5 m of margin outside.
    # Inside there are 40 x 30 x 25 voxels. Those touching a face (centre 0.05 m from it) are
    # blocked, so the flood fill reaches the 38 x 28 x 23 core; the 40 x 30 x 25 - 38 x 28 x 23
    # voxels of the outer shell all hold samples and touch the core by a face, edge or corner,
    # so they form the surface layer. The voxels just outside the faces also hold samples but are
    # two voxels from the core, so they stay out.
    area = _area([_box([0, 0, 0], [4, 3, 2.5])], [-0.5, -0.5, -0.5], [4.5, 3.5, 3.0], [2, 1.5, 1.2])
    truth = compute_ground_truth(area)
    core = 38 * 28 * 23
    shell = 40 * 30 * 25 - core
    assert np.count_nonzero(truth.observable) == core + shell == 30000
    assert truth.observable_volume_m3 == pytest.approx(30.0)
    # Exactly the inside: grid indices 5..44, 5..34, 5..29.
    np.testing.assert_array_equal(np.argwhere(truth.observable).min(axis=0), [5, 5, 5])
    np.testing.assert_array_equal(np.argwhere(truth.observable).max(axis=0), [44, 34, 29])


def test_surface_cloud_lies_on_the_box_and_covers_all_faces() -> None:
    box = _box([0, 0, 0], [4, 3, 2.5])
    area = _area([box], [-0.5, -0.5, -0.5], [4.5, 3.5, 3.0], [2, 1.5, 1.2])
    spacing = 0.05
    truth = compute_ground_truth(area, sample_spacing=spacing)
    pts = truth.surface_points
    assert pts.dtype == np.float32
    assert float(_distance_to(box, pts).max()) < 1e-5
    # About one sample per spacing^2 of the 2 (12 + 10 + 7.5) = 59 m^2 surface.
    assert len(pts) == pytest.approx(59.0 / spacing**2, rel=0.02)
    for axis, (lo, hi) in enumerate([(0.0, 4.0), (0.0, 3.0), (0.0, 2.5)]):
        other = [a for a in range(3) if a != axis]
        face_area = float(np.prod([[4.0, 3.0, 2.5][a] for a in other]))
        for value in (lo, hi):
            on_face = np.abs(pts[:, axis] - value) < 1e-5
            assert on_face.sum() == pytest.approx(face_area / spacing**2, rel=0.05)


def test_box_cut_through_voxel_centres() -> None:
    # Offset by half a voxel, each face runs through a layer of voxel centres: x from 0.05 to
    # 4.05 passes through the centres of voxels 0 and 40. Those blocked layers hold the surface
    # and touch the reachable voxels 1..39, so 41 voxels count along x, 31 along y, 26 along z.
    area = _area(
        [_box([0.05, 0.05, 0.05], [4.05, 3.05, 2.55])], [0, 0, 0], [4.2, 3.2, 2.7], [2, 1.5, 1.2]
    )
    truth = compute_ground_truth(area, sample_spacing=0.05)
    assert np.count_nonzero(truth.observable) == 41 * 31 * 26


def test_winding_does_not_matter() -> None:
    lo, hi, start = [-0.5, -0.5, -0.5], [4.5, 3.5, 3.0], [2, 1.5, 1.2]
    inward = compute_ground_truth(
        _area([_box([0, 0, 0], [4, 3, 2.5])], lo, hi, start), sample_spacing=0.1
    )
    outward = compute_ground_truth(
        _area([_box([0, 0, 0], [4, 3, 2.5], inward=False)], lo, hi, start), sample_spacing=0.1
    )
    np.testing.assert_array_equal(inward.observable, outward.observable)


def test_only_the_box_with_the_start_counts() -> None:
    first = _box([0, 0, 0], [4, 3, 2.5])
    second = _box([5, 0, 0], [8, 3, 2.5])
    area = _area([first, second], [-0.5, -0.5, -0.5], [8.5, 3.5, 3.0], [2, 1.5, 1.2])
    truth = compute_ground_truth(area, sample_spacing=0.05)
    assert np.count_nonzero(truth.observable) == 40 * 30 * 25
    assert truth.surface_points[:, 0].max() <= 4.0 + 1e-5
    assert float(_distance_to(first, truth.surface_points).max()) < 1e-5


def test_open_sheet_off_the_grid_does_not_leak() -> None:
    # A zero-thickness sheet at x = 2.03 (not on a voxel face) splits the box; the start is on the
    # low side. Voxel 20 (x in [2.0, 2.1]) has its centre 0.02 m from the sheet and is blocked;
    # voxels 0..19 lie on the start side, and voxel 20 holds the sheet, so 21 of 40 count along x.
    sheet = trimesh.Trimesh(
        vertices=[[2.03, 0, 0], [2.03, 3, 0], [2.03, 3, 2.5], [2.03, 0, 2.5]],
        faces=[[0, 1, 2], [0, 2, 3]],
    )
    area = _area([_box([0, 0, 0], [4, 3, 2.5]), sheet], [0, 0, 0], [4, 3, 2.5], [1, 1.5, 1.2])
    truth = compute_ground_truth(area, sample_spacing=0.05)
    assert np.count_nonzero(truth.observable) == 21 * 30 * 25
    assert not truth.observable[21:].any()


def test_start_inside_a_wall_is_rejected() -> None:
    area = _area([_box([0, 0, 0], [4, 3, 2.5])], [0, 0, 0], [4, 3, 2.5], [0.02, 1.5, 1.2])
    with pytest.raises(ValueError, match="free space"):
        compute_ground_truth(area)


def test_maze_observable_volume_and_speed() -> None:
    maze = build_maze(seed=0)
    began = time.perf_counter()
    truth = compute_ground_truth(maze)
    elapsed = time.perf_counter() - began
    # Free floor: 100 cell interiors of 1.75 x 1.75 m plus each open passage, 1.75 x 0.25 m.
    # Walls sit mid-voxel (faces at .125 / .875 m), so the observable voxels are the free space
    # plus, behind every wall face, the 0.025 m of its surface voxel that lies inside the wall;
    # floor and ceiling lie on voxel faces and add nothing.
    open_x, open_y = maze_passages(np.random.default_rng(0))
    interior = CELL_SIZE - WALL_THICKNESS
    floor = CELLS**2 * interior**2 + int(open_x.sum() + open_y.sum()) * interior * WALL_THICKNESS
    free_volume = floor * HEIGHT
    assert free_volume == pytest.approx(882.65625)
    mesh = trimesh.Trimesh(maze.vertices, maze.triangles, process=False)
    wall_area = mesh.area - 2.0 * floor
    layer = wall_area * 0.025  # a wall face at .125 m: 0.025 m of its 0.1 m voxel is behind it
    assert truth.observable_volume_m3 == pytest.approx(free_volume + layer, rel=0.005)
    # Every sample of the closed maze faces the free space, so every sample is perceivable.
    assert len(truth.surface_points) == pytest.approx(mesh.area / DEFAULT_SAMPLE_SPACING**2,
                                                      rel=0.01)
    # About 4 s alone on a core (two passes of 2 cm samples); the bound leaves room for a busy
    # shared machine.
    assert elapsed < 20.0


def test_disk_cache_round_trip(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("FLYBO_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(ground_truth, "_memory_cache", {})
    area = _area([_box([0, 0, 0], [2, 2, 2])], [0, 0, 0], [2, 2, 2], [1, 1, 1])
    first = load_ground_truth(area)
    path = ground_truth_path(area)
    assert path == tmp_path / "ground_truth" / f"{area.content_hash}.npz"
    assert path.is_file()
    assert list(path.parent.iterdir()) == [path]
    assert load_ground_truth(area) is first

    monkeypatch.setattr(ground_truth, "_memory_cache", {})

    def fail(*args: object, **kwargs: object) -> None:
        raise AssertionError("recomputed instead of reading the cache")

    monkeypatch.setattr(ground_truth, "compute_ground_truth", fail)
    second = load_ground_truth(area)
    assert second is not first
    np.testing.assert_array_equal(second.observable, first.observable)
    np.testing.assert_array_equal(second.surface_points, first.surface_points)
    assert second.voxel_size == first.voxel_size


def test_corrupt_cache_file_is_recomputed(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("FLYBO_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(ground_truth, "_memory_cache", {})
    area = _area([_box([0, 0, 0], [2, 2, 2])], [0, 0, 0], [2, 2, 2], [1, 1, 1])
    path = ground_truth_path(area)
    path.parent.mkdir(parents=True)
    path.write_bytes(b"not an npz")
    truth = load_ground_truth(area)
    assert np.count_nonzero(truth.observable) == 20**3
    assert ground_truth._read(path, area) is not None


# Builds a 2 m box area's ground truth in a fresh process, counting its computations in a file;
# the computation sleeps first, so two such processes started together both miss the cache.
_BUILDER = """
import sys, time
from pathlib import Path
import numpy as np
import trimesh
from areas import ground_truth
from areas.area import Area, AreaInfo, StartPose
from areas.build_lock import load_ground_truth_once

box = trimesh.creation.box(extents=[2.0, 2.0, 2.0],
                           transform=trimesh.transformations.translation_matrix([1.0, 1.0, 1.0]))
box.invert()
area = Area(name="test", vertices=np.asarray(box.vertices, dtype=np.float64),
            triangles=np.asarray(box.faces, dtype=np.int32), bounds_min=np.zeros(3),
            bounds_max=np.full(3, 2.0), start=StartPose(position=np.ones(3), yaw=0.0),
            plateau_s=10.0, voxel_size=0.1,
            info=AreaInfo(title="TEST", rooms=1, levels=1, complexity="low", indoor=True))
compute = ground_truth.compute_ground_truth

def counted(a):
    with open(sys.argv[1], "a") as f:
        f.write("computed\\n")
    time.sleep(2.0)
    return compute(a)

ground_truth.compute_ground_truth = counted
truth = load_ground_truth_once(area)
print(int(np.count_nonzero(truth.observable)))
"""


@pytest.mark.slow
def test_processes_missing_the_cache_at_once_compute_it_once(tmp_path: Path) -> None:
    counter = tmp_path / "computations"
    env = {**os.environ, "FLYBO_CACHE_DIR": str(tmp_path / "cache"),
           "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
    children = [subprocess.Popen([sys.executable, "-c", _BUILDER, str(counter)], env=env,
                                 stdout=subprocess.PIPE, text=True) for _ in range(2)]
    outputs = [child.communicate(timeout=300)[0] for child in children]
    assert [child.returncode for child in children] == [0, 0]
    assert [int(out.split()[-1]) for out in outputs] == [20**3, 20**3]
    assert counter.read_text().splitlines() == ["computed"]
    assert len(list((tmp_path / "cache" / "ground_truth").iterdir())) == 1
