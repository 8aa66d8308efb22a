"""The compiled surface sampling places the draws and finds their voxels as the array expressions
do, bit for bit; the draws themselves are array expressions (`areas.surface_samples.draw`)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pytest

from areas.surface_samples import Draws, draw, points_of, side_voxels

FloatArray = npt.NDArray[np.float64]


def _reference_points(d: Draws) -> tuple[FloatArray, FloatArray]:
    """The compiled loops' placement as array expressions over the same draws."""
    face = np.repeat(np.arange(len(d.counts)), d.counts)
    u, v = d.u.copy(), d.v.copy()
    outside = u + v > 1.0
    u[outside] = 1.0 - u[outside]
    v[outside] = 1.0 - v[outside]
    points = d.origin[face] + u[:, None] * d.edge1[face] + v[:, None] * d.edge2[face]
    return points, d.normal[face]


def _reference_voxels(points: FloatArray, origin: FloatArray, voxel_size: float,
                      shape: tuple[int, int, int]) -> tuple[npt.NDArray[np.int64],
                                                            npt.NDArray[np.bool_]]:
    dims = np.array(shape)
    ijk = np.floor((points - origin) / voxel_size).astype(np.int64)
    inside = np.all((ijk >= 0) & (ijk < dims), axis=1)
    flat = np.ravel_multi_index(tuple(np.clip(ijk, 0, dims - 1).T), shape)
    return flat, inside


def _mesh(kind: str, rng: np.random.Generator) -> tuple[FloatArray, npt.NDArray[np.int64]]:
    if kind == "random":
        vertices = rng.uniform(-0.5, 4.5, size=(300, 3))
        triangles = rng.integers(0, len(vertices), size=(200, 3))
        triangles[:5, 1] = triangles[:5, 0]  # degenerate: no samples, zero normal
        return vertices, triangles
    # Axis-aligned squares on voxel faces (0.1 m grid), as MAZE's walls: samples lie exactly on
    # faces, where the tiny step decides the side.
    squares = []
    for k in range(6):
        z = 0.1 * k
        squares.append([[0.0, 0.0, z], [2.0, 0.0, z], [2.0, 2.0, z], [0.0, 2.0, z]])
        x = 0.3 * k
        squares.append([[x, 0.0, 0.0], [x, 0.0, 2.0], [x, 2.0, 2.0], [x, 2.0, 0.0]])
    vertices = np.array(squares, dtype=np.float64).reshape(-1, 3)
    base = np.arange(0, len(vertices), 4)[:, None]
    triangles = np.concatenate([base + np.array([0, 1, 2]), base + np.array([0, 2, 3])])
    return vertices, triangles.astype(np.int64)


@pytest.mark.parametrize("kind", ["random", "voxel faces"])
def test_points_and_side_voxels_match_the_array_expressions(kind: str) -> None:
    rng = np.random.default_rng(7)
    vertices, triangles = _mesh(kind, rng)
    spacing, seed = 0.02, 11
    draws = draw(vertices, triangles, spacing, np.random.default_rng(seed))
    points, normals = points_of(draws)
    ref_points, ref_normals = _reference_points(draws)
    assert len(points) > 10_000
    assert np.array_equal(points, ref_points)
    assert np.array_equal(normals, ref_normals)

    origin, voxel_size, shape = np.array([0.0, 0.0, 0.0]), 0.1, (30, 20, 25)
    low, high = origin - 1e-9, origin + np.array(shape) * voxel_size + 1e-9
    step = 1e-4 * voxel_size
    kept32, side_a, inside_a, side_b, inside_b = side_voxels(
        draws, low, high, step, origin, voxel_size, shape)
    keep = np.all((ref_points >= low) & (ref_points <= high), axis=1)
    assert 0 < keep.sum() < len(keep) or kind == "voxel faces"
    ref_kept, ref_normals = ref_points[keep], ref_normals[keep]
    ref_a, ref_in_a = _reference_voxels(ref_kept + step * ref_normals, origin, voxel_size, shape)
    ref_b, ref_in_b = _reference_voxels(ref_kept - step * ref_normals, origin, voxel_size, shape)
    assert np.array_equal(kept32, ref_kept.astype(np.float32))
    assert np.array_equal(side_a, ref_a) and np.array_equal(inside_a, ref_in_a)
    assert np.array_equal(side_b, ref_b) and np.array_equal(inside_b, ref_in_b)
    # On voxel faces the two sides differ: the step reaches both voxels sharing the face.
    if kind == "voxel faces":
        assert np.count_nonzero(side_a != side_b) > len(side_a) // 2


def test_no_triangles_draw_nothing() -> None:
    d = draw(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64), 0.02, np.random.default_rng(0))
    points, normals = points_of(d)
    assert points.shape == (0, 3) and normals.shape == (0, 3)
