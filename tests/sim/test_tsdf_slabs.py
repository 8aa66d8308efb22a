"""Marching cubes in slabs: the same mesh as one extraction of the whole grid."""

from __future__ import annotations

import itertools

import numpy as np
import numpy.typing as npt
import pytest

from sim.camera import DepthCamera
from sim.geometry import Pose
from sim.open3d_any import o3c
from sim.tsdf import TsdfConfig, TsdfVolume
from sim.tsdf_slabs import (
    _pair_equal_rows,
    _plane_is_ambiguous,
    _slab_starts,
    block_grid,
    extract_mesh,
    mesh_in_slabs,
)

VOXEL = 0.05
RES = 8
THRESHOLD = 1.0


def _grid(keys: npt.NDArray[np.int32], tsdf: npt.NDArray[np.float32],
          weight: npt.NDArray[np.float32]) -> object:
    grid = block_grid(VOXEL, RES, max(len(keys), 100))
    buf, _ = grid.hashmap().activate(o3c.Tensor(np.ascontiguousarray(keys)))
    rows = buf.numpy().astype(np.int64)
    grid.attribute("tsdf").numpy()[rows] = tsdf
    grid.attribute("weight").numpy()[rows] = weight
    return grid


def _field_grid(seed: int, quantum: float | None = None) -> object:
    """Blocks over a 6 x 4 x 3 block region (some missing), holding the truncated distance to
    a few random spheres, with random weights (some below the threshold)."""
    rng = np.random.default_rng(seed)
    keys = np.array([(x, y, z) for x in range(-2, 4) for y in range(4) for z in range(3)
                     if rng.random() > 0.1], dtype=np.int32)
    local = np.arange(RES)
    # (N, z, y, x) voxel coordinates: Open3D keeps a block's voxels with x fastest.
    gz, gy, gx = np.meshgrid(local, local, local, indexing="ij")
    centres = rng.uniform([-16, 0, 0], [32, 32, 24], size=(6, 3))
    radii = rng.uniform(3, 9, size=6)
    x = keys[:, 0, None, None, None] * RES + gx
    y = keys[:, 1, None, None, None] * RES + gy
    z = keys[:, 2, None, None, None] * RES + gz
    points = np.stack([x, y, z], axis=-1).astype(np.float64)
    dist = np.min(np.linalg.norm(points[..., None, :] - centres, axis=-1) - radii, axis=-1)
    tsdf = np.clip(dist / 3.0, -1.0, 1.0)
    if quantum is not None:  # many exact zeros, as coarse fusion may leave
        tsdf = np.round(tsdf / quantum) * quantum
    weight = rng.choice([0.0, 1.0, 2.0, 5.0], p=[0.05, 0.05, 0.3, 0.6], size=tsdf.shape)
    return _grid(keys, tsdf[..., None].astype(np.float32), weight[..., None].astype(np.float32))


def _fused_box_grid() -> TsdfVolume:
    sx, sy, sz = 4.0, 3.0, 2.5
    v = np.array([[x, y, z] for x in (0, sx) for y in (0, sy) for z in (0, sz)], dtype=float)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tris = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))], dtype=np.int32)
    camera = DepthCamera(v, tris)
    volume = TsdfVolume(camera.config.intrinsic_matrix(), 5.0, TsdfConfig())
    for yaw in np.arange(0.0, 2 * np.pi, 0.4):
        for height in (0.8, 1.7):
            pose = Pose(np.array([2.0, 1.5, height]), float(yaw))
            volume.integrate(camera.render(pose).depth, pose)
    return volume


def _starts(grid: object, slab_blocks: int) -> list[int]:
    hashmap = grid.hashmap()  # type: ignore[attr-defined]
    rows = hashmap.active_buf_indices().numpy().astype(np.int64)
    keys = hashmap.key_tensor().numpy()[rows]
    views = (grid.attribute("tsdf").numpy(), grid.attribute("weight").numpy())  # type: ignore
    return _slab_starts(keys, *views, rows, slab_blocks, VOXEL, THRESHOLD)


def _sorted_rows(rows: npt.NDArray[np.generic]) -> npt.NDArray[np.generic]:
    return rows[np.lexsort(rows.T[::-1])]


def _triangle_set(vertices: npt.NDArray[np.float32],
                  triangles: npt.NDArray[np.int32]) -> npt.NDArray[np.int64]:
    """Each triangle as its 9 coordinates' bits, rotated to start at its smallest corner (the
    winding kept), sorted."""
    bits = vertices.view(np.uint32).astype(np.int64)[triangles]  # (F, 3, 3)
    key = (bits[:, :, 0] << 32 | bits[:, :, 1]) * 3 + np.argsort(np.argsort(bits[:, :, 2], 1), 1)
    start = np.argmin(key, axis=1)
    order = (start[:, None] + np.arange(3)) % 3
    rotated = np.take_along_axis(bits, order[:, :, None], axis=1).reshape(len(triangles), 9)
    return _sorted_rows(rotated)


def _assert_same_mesh(grid: object, slab_blocks: int) -> int:
    whole_v, whole_t = extract_mesh(grid, THRESHOLD)
    slab_v64, slab_t = mesh_in_slabs(grid, VOXEL, THRESHOLD, slab_blocks)
    assert slab_v64.dtype == np.float64
    slab_v = slab_v64.astype(np.float32)  # exact: Open3D's positions are float32
    assert len(whole_v) > 0
    assert slab_v.shape == whole_v.shape and slab_t.shape == whole_t.shape
    np.testing.assert_array_equal(_sorted_rows(slab_v), _sorted_rows(whole_v))
    np.testing.assert_array_equal(_triangle_set(slab_v, slab_t), _triangle_set(whole_v, whole_t))
    assert slab_t.min() >= 0 and slab_t.max() < len(slab_v)
    return len(whole_v)


@pytest.mark.parametrize("seed", range(4))
def test_every_plane_a_boundary_gives_the_whole_grids_mesh(seed: int) -> None:
    grid = _field_grid(seed)
    hashmap = grid.hashmap()  # type: ignore[attr-defined]
    keys = hashmap.key_tensor().numpy()[hashmap.active_buf_indices().numpy()]
    _assert_same_mesh(grid, slab_blocks=1)
    _assert_same_mesh(grid, slab_blocks=30)
    assert len(np.unique(keys[:, 0])) == 6


@pytest.mark.parametrize("quantum", [1 / 8, 1 / 64])
def test_exact_zeros_on_boundaries_keep_the_mesh(quantum: float) -> None:
    grid = _field_grid(7, quantum=quantum)
    _assert_same_mesh(grid, slab_blocks=1)
    assert len(_starts(grid, 1)) >= 2  # some planes still cut: not one whole extraction


def test_a_fused_surface_meshes_the_same_in_slabs() -> None:
    volume = _fused_box_grid()
    grid = volume._grid
    n = grid.hashmap().size()
    assert n > 100
    _assert_same_mesh(grid, slab_blocks=1)
    _assert_same_mesh(grid, slab_blocks=n // 5)
    vertices, triangles = volume.mesh()
    assert vertices.dtype == np.float64 and triangles.dtype == np.int32 and len(vertices) > 1000


def test_slabs_hold_at_most_the_asked_blocks_where_a_plane_allows() -> None:
    grid = _field_grid(1)
    hashmap = grid.hashmap()  # type: ignore[attr-defined]
    rows = hashmap.active_buf_indices().numpy().astype(np.int64)
    keys = hashmap.key_tensor().numpy()[rows]
    tsdf = grid.attribute("tsdf").numpy()  # type: ignore[attr-defined]
    weight = grid.attribute("weight").numpy()  # type: ignore[attr-defined]
    starts = _slab_starts(keys, tsdf, weight, rows, 30, VOXEL, THRESHOLD)
    edges = [*starts, int(keys[:, 0].max()) + 1]
    per_plane = max(np.count_nonzero(keys[:, 0] == x) for x in np.unique(keys[:, 0]))
    for lo, hi in itertools.pairwise(edges):
        inside = np.count_nonzero((keys[:, 0] >= lo) & (keys[:, 0] < hi))
        assert inside <= max(30, per_plane) or hi - lo == 1
    assert len(starts) >= 3
    assert _slab_starts(keys, tsdf, weight, rows, 10**6, VOXEL, THRESHOLD) == [
        int(keys[:, 0].min())]


def test_a_plane_whose_voxel_sits_on_the_surface_between_two_crossings_is_ambiguous() -> None:
    keys = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0]], dtype=np.int32)
    tsdf = np.full((3, RES, RES, RES, 1), 0.5, dtype=np.float32)
    weight = np.full((3, RES, RES, RES, 1), 5.0, dtype=np.float32)
    # Block 1's first x plane: one voxel a hair below zero, its neighbours positive: the vertices
    # of its crossing edges round onto it.
    tsdf[1, 3, 4, 0, 0] = -1e-9
    grid = _grid(keys, tsdf, weight)
    hashmap = grid.hashmap()  # type: ignore[attr-defined]
    rows = hashmap.active_buf_indices().numpy().astype(np.int64)
    got_keys = hashmap.key_tensor().numpy()[rows]
    views = (grid.attribute("tsdf").numpy(), grid.attribute("weight").numpy())  # type: ignore
    assert _plane_is_ambiguous(1, got_keys, *views, rows, VOXEL, THRESHOLD)
    assert not _plane_is_ambiguous(2, got_keys, *views, rows, VOXEL, THRESHOLD)
    assert _slab_starts(got_keys, *views, rows, 1, VOXEL, THRESHOLD) == [0, 2]
    _assert_same_mesh(grid, slab_blocks=1)


def test_vertices_on_a_plane_pair_one_for_one_even_when_some_coincide() -> None:
    a = np.array([[1, 2, 3], [1, 5, 6], [1, 2, 3], [1, 0, -0.0]], dtype=np.float32)
    b = np.array([[1, 2, 3], [1, 9, 9], [1, 0, 0], [1, 5, 6]], dtype=np.float32)
    i, j = _pair_equal_rows(a, b)
    assert sorted(zip(i.tolist(), j.tolist(), strict=True)) in ([(0, 0), (1, 3), (3, 2)],
                                                               [(1, 3), (2, 0), (3, 2)])
    i, j = _pair_equal_rows(a[[1, 3]], b)
    assert sorted(zip(i.tolist(), j.tolist(), strict=True)) == [(0, 3), (1, 2)]
