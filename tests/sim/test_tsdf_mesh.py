"""The compiled marching cubes: Open3D's mesh, vertex for vertex and triangle for triangle."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pytest
from pydantic import ValidationError

from areas import load_area
from sim.camera import DepthCamera
from sim.geometry import Pose
from sim.open3d_any import o3c
from sim.tsdf import TsdfConfig, TsdfVolume
from sim.tsdf_blocks import block_grid
from sim.tsdf_mesh import EDGE_SHIFTS, case_tables, marching_cubes, open3d_mesh, same_mesh

VOXEL = 0.05
RES = 8
THRESHOLD = 1.0


def _grid(keys: npt.NDArray[np.int32], tsdf: npt.NDArray[np.float32],
          weight: npt.NDArray[np.float32], res: int = RES) -> object:
    grid = block_grid(VOXEL, res, max(len(keys), 100))
    buf, _ = grid.hashmap().activate(o3c.Tensor(np.ascontiguousarray(keys)))
    rows = buf.numpy().astype(np.int64)
    grid.attribute("tsdf").numpy()[rows] = tsdf
    grid.attribute("weight").numpy()[rows] = weight
    return grid


def _field(seed: int, quantum: float | None = None, res: int = RES) -> tuple[
        npt.NDArray[np.int32], npt.NDArray[np.float32], npt.NDArray[np.float32]]:
    """Blocks over a 6 x 4 x 3 block region (some missing), holding the truncated distance to
    a few random spheres, with random weights (some at or below the threshold)."""
    rng = np.random.default_rng(seed)
    keys = np.array([(x, y, z) for x in range(-2, 4) for y in range(4) for z in range(3)
                     if rng.random() > 0.1], dtype=np.int32)
    local = np.arange(res)
    # (N, z, y, x) voxel coordinates: Open3D keeps a block's voxels with x fastest.
    gz, gy, gx = np.meshgrid(local, local, local, indexing="ij")
    scale = res / RES
    centres = rng.uniform([-16, 0, 0], [32, 32, 24], size=(6, 3)) * scale
    radii = rng.uniform(3, 9, size=6) * scale
    x = keys[:, 0, None, None, None] * res + gx
    y = keys[:, 1, None, None, None] * res + gy
    z = keys[:, 2, None, None, None] * res + gz
    points = np.stack([x, y, z], axis=-1).astype(np.float64)
    dist = np.min(np.linalg.norm(points[..., None, :] - centres, axis=-1) - radii, axis=-1)
    tsdf = np.clip(dist / 3.0, -1.0, 1.0)
    if quantum is not None:  # many exact zeros, as coarse fusion may leave
        tsdf = np.round(tsdf / quantum) * quantum
    weight = rng.choice([0.0, 1.0, 2.0, 5.0], p=[0.05, 0.05, 0.3, 0.6], size=tsdf.shape)
    return keys, tsdf[..., None].astype(np.float32), weight[..., None].astype(np.float32)


def _fused_grid(vertices: npt.NDArray[np.float64], triangles: npt.NDArray[np.int32],
                poses: list[Pose], noise_m: float) -> TsdfVolume:
    camera = DepthCamera(vertices, triangles)
    volume = TsdfVolume(camera.config.intrinsic_matrix(), 5.0, TsdfConfig())
    rng = np.random.default_rng(3)
    for pose in poses:
        depth = camera.render(pose).depth
        volume.integrate(depth + rng.normal(0.0, noise_m, depth.shape).astype(np.float32), pose)
    return volume


def _box_volume() -> TsdfVolume:
    sx, sy, sz = 4.0, 3.0, 2.5
    v = np.array([[x, y, z] for x in (0, sx) for y in (0, sy) for z in (0, sz)], dtype=float)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tris = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))], dtype=np.int32)
    poses = [Pose(np.array([2.0, 1.5, h]), float(yaw))
             for yaw in np.arange(0.0, 2 * np.pi, 0.4) for h in (0.8, 1.7)]
    return _fused_grid(v, tris, poses, 0.0)


def _assert_open3ds_mesh(grid: object) -> int:
    vertices, triangles = marching_cubes(grid, VOXEL, THRESHOLD)
    assert vertices.dtype == np.float64 and triangles.dtype == np.int32
    reference = open3d_mesh(grid, THRESHOLD)
    assert len(reference[0]) > 0
    assert same_mesh((vertices, triangles), reference)
    assert triangles.min() >= 0 and triangles.max() < len(vertices)
    return len(vertices)


@pytest.mark.parametrize("seed", range(4))
def test_random_fields_mesh_as_open3d_meshes_them(seed: int) -> None:
    _assert_open3ds_mesh(_grid(*_field(seed)))


@pytest.mark.parametrize("quantum", [1 / 8, 1 / 64])
def test_exact_zeros_mesh_as_open3d_meshes_them(quantum: float) -> None:
    _assert_open3ds_mesh(_grid(*_field(7, quantum=quantum)))


@pytest.mark.parametrize("res", [4, 13])
def test_other_block_sizes_mesh_as_open3d_meshes_them(res: int) -> None:
    _assert_open3ds_mesh(_grid(*_field(5, res=res), res=res))


def test_blocks_larger_than_the_codes_hold_are_refused() -> None:
    keys, tsdf, weight = _field(5, res=14)
    with pytest.raises(ValueError, match="at most 13"):
        marching_cubes(_grid(keys, tsdf, weight, res=14), VOXEL, THRESHOLD)
    with pytest.raises(ValidationError, match="block_resolution"):
        TsdfConfig(block_resolution=14)


def test_vertices_that_coincide_are_kept_apart() -> None:
    """A voxel a hair below zero among positive ones: the vertices of its six edges round
    onto it, and stay six vertices, as in Open3D's mesh."""
    keys = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0]], dtype=np.int32)
    tsdf = np.full((3, RES, RES, RES, 1), 0.5, dtype=np.float32)
    weight = np.full((3, RES, RES, RES, 1), 5.0, dtype=np.float32)
    tsdf[1, 3, 4, 0, 0] = -1e-9
    grid = _grid(keys, tsdf, weight)
    vertices, _ = marching_cubes(grid, VOXEL, THRESHOLD)
    assert len(vertices) == 6
    assert len(np.unique(vertices.astype(np.float32), axis=0)) == 1
    _assert_open3ds_mesh(grid)


def test_a_fused_box_meshes_as_open3d_meshes_it() -> None:
    volume = _box_volume()
    assert _assert_open3ds_mesh(volume.grid) > 1000
    vertices, triangles = volume.mesh()
    assert same_mesh((vertices, triangles), open3d_mesh(volume.grid, THRESHOLD))


def test_a_noisy_fused_view_of_an_area_meshes_as_open3d_meshes_it() -> None:
    area = load_area("maze")
    start = np.asarray(area.start.position, dtype=float)
    poses = [Pose(start + np.array([dx, 0.0, dz]), float(yaw))
             for yaw in np.arange(0.0, 2 * np.pi, 0.5) for dx, dz in ((0.0, 0.0), (0.3, 0.4))]
    volume = _fused_grid(np.asarray(area.vertices), np.asarray(area.triangles), poses, 0.01)
    assert _assert_open3ds_mesh(volume.grid) > 10_000


def test_the_mesh_is_the_same_arrays_whatever_slots_hold_the_blocks() -> None:
    keys, tsdf, weight = _field(2)
    first = marching_cubes(_grid(keys, tsdf, weight), VOXEL, THRESHOLD)
    backwards = marching_cubes(_grid(keys[::-1], tsdf[::-1], weight[::-1]), VOXEL, THRESHOLD)
    np.testing.assert_array_equal(first[0], backwards[0])
    np.testing.assert_array_equal(first[1], backwards[1])


def test_a_grid_without_surface_gives_an_empty_mesh() -> None:
    empty = marching_cubes(block_grid(VOXEL, RES, 100), VOXEL, THRESHOLD)
    assert empty[0].shape == (0, 3) and empty[1].shape == (0, 3)
    keys = np.array([[0, 0, 0], [1, 0, 0]], dtype=np.int32)
    flat = np.full((2, RES, RES, RES, 1), 0.5, dtype=np.float32)
    vertices, triangles = marching_cubes(
        _grid(keys, flat, np.full_like(flat, 5.0)), VOXEL, THRESHOLD)
    assert vertices.shape == (0, 3) and triangles.shape == (0, 3)


def test_each_case_uses_exactly_its_sign_change_edges() -> None:
    edges, table = case_tables()
    assert edges[0] == edges[255] == 0 and (table[[0, 255]] == -1).all()
    for case in range(1, 255):
        used = table[case][table[case] >= 0]
        assert len(used) % 3 == 0 and 3 <= len(used) <= 15
        assert sum(1 << int(e) for e in np.unique(used)) == edges[case]
        assert edges[case] == edges[255 - case]  # a case and its complement cut the same edges
    assert EDGE_SHIFTS.shape == (12, 4) and len({tuple(r) for r in EDGE_SHIFTS.tolist()}) == 12


def test_same_mesh_tells_a_flipped_or_moved_triangle_from_a_turned_one() -> None:
    vertices, triangles = marching_cubes(_grid(*_field(0)), VOXEL, THRESHOLD)
    assert same_mesh((vertices, np.roll(triangles, 1, axis=1)), (vertices, triangles))
    assert same_mesh((vertices[::-1], len(vertices) - 1 - triangles), (vertices, triangles))
    flipped = triangles.copy()
    flipped[0] = flipped[0, ::-1]
    assert not same_mesh((vertices, flipped), (vertices, triangles))
    moved = vertices.copy()
    moved[triangles[0, 0], 2] = np.nextafter(np.float32(moved[triangles[0, 0], 2]), np.inf)
    assert not same_mesh((moved, triangles), (vertices, triangles))
