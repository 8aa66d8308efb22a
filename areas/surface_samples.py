"""Uniform samples of a triangle mesh's surface, and the voxels either side of each sample.

`draw` takes every random number a sampling uses, in one fixed order (per triangle the
fractional sample's coin, then per sample the two barycentric coordinates); the compiled loops
turn the draws into points with the same float64 operations in the same order as the array
expression ``c0 + u * e1 + v * e2`` (no fused multiply-add), so the samples of a seed never
depend on how they are computed. `ground_truth` reads them chunk by chunk; a sample is looked up
a tiny step either side of its triangle along the normal (see `areas.ground_truth`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]


@dataclass(frozen=True)
class Draws:
    """The random draws of one sampling of a triangle set, and its triangles' geometry.

    Attributes:
        origin: (F, 3) float64 first corner of each triangle, metres.
        edge1, edge2: (F, 3) float64 second and third corner minus the first.
        normal: (F, 3) float64 unit normal by the winding (zero for a degenerate triangle).
        counts: (F,) int64 samples per triangle.
        u, v: (N,) float64 barycentric draws in [0, 1), N = counts.sum(), triangle by triangle.
    """

    origin: FloatArray
    edge1: FloatArray
    edge2: FloatArray
    normal: FloatArray
    counts: IntArray
    u: FloatArray
    v: FloatArray


def draw(vertices: FloatArray, triangles: npt.NDArray[np.integer], spacing: float,
         rng: np.random.Generator) -> Draws:
    """Each triangle gets ``floor(area / spacing**2)`` samples plus one with probability equal to
    the remainder, so large faces are covered evenly and the total matches the area.

    Args:
        vertices: (V, 3) metres.
        triangles: (F, 3) vertex indices.
        spacing: about one sample per ``spacing**2`` square metres.
        rng: random generator.
    """
    corners = vertices[triangles]  # (F, 3, 3)
    e1 = corners[:, 1] - corners[:, 0]
    e2 = corners[:, 2] - corners[:, 0]
    cross = np.cross(e1, e2)
    twice_area = np.linalg.norm(cross, axis=1)
    expected = 0.5 * twice_area / spacing**2
    counts = np.floor(expected).astype(np.int64)
    counts += rng.random(len(counts)) < (expected - counts)
    total = int(counts.sum())
    u = rng.random(total)
    v = rng.random(total)
    with np.errstate(invalid="ignore", divide="ignore"):
        unit = np.where(twice_area[:, None] > 0.0, cross / twice_area[:, None], 0.0)
    return Draws(np.ascontiguousarray(corners[:, 0]), e1, e2, unit, counts, u, v)


@numba.njit(cache=True, inline="always")
def _folded(u: float, v: float) -> tuple[float, float]:
    # The fold keeps the distribution uniform over the triangle.
    if u + v > 1.0:
        return 1.0 - u, 1.0 - v
    return u, v


@numba.njit(cache=True, inline="always")
def _point(d_origin: FloatArray, d_e1: FloatArray, d_e2: FloatArray, t: int, u: float,
           v: float, axis: int) -> float:
    p = d_origin[t, axis] + u * d_e1[t, axis]
    return p + v * d_e2[t, axis]


@numba.njit(cache=True)
def _points(origin: FloatArray, e1: FloatArray, e2: FloatArray, normal: FloatArray,
            counts: IntArray, u: FloatArray, v: FloatArray) -> tuple[FloatArray, FloatArray]:
    n = u.shape[0]
    points = np.empty((n, 3), dtype=np.float64)
    normals = np.empty((n, 3), dtype=np.float64)
    s = 0
    for t in range(counts.shape[0]):
        for _ in range(counts[t]):
            fu, fv = _folded(u[s], v[s])
            for axis in range(3):
                points[s, axis] = _point(origin, e1, e2, t, fu, fv, axis)
                normals[s, axis] = normal[t, axis]
            s += 1
    return points, normals


def points_of(d: Draws) -> tuple[FloatArray, FloatArray]:
    """(N, 3) float64 sample points and (N, 3) the unit normals of their triangles."""
    return _points(d.origin, d.edge1, d.edge2, d.normal, d.counts, d.u, d.v)


@numba.njit(cache=True)
def _flat_voxel(p: FloatArray, origin: FloatArray, voxel_size: float,
                shape: IntArray) -> tuple[int, bool]:
    inside = True
    flat = 0
    for axis in range(3):
        i = int(np.floor((p[axis] - origin[axis]) / voxel_size))
        if i < 0 or i >= shape[axis]:
            inside = False
        flat = flat * shape[axis] + min(max(i, 0), shape[axis] - 1)
    return flat, inside


@numba.njit(cache=True)
def _sides(origin: FloatArray, e1: FloatArray, e2: FloatArray, normal: FloatArray,
           counts: IntArray, u: FloatArray, v: FloatArray, low: FloatArray, high: FloatArray,
           step: float, grid_origin: FloatArray, voxel_size: float, shape: IntArray,
           ) -> tuple[npt.NDArray[np.float32], IntArray, BoolArray, IntArray, BoolArray]:
    n = u.shape[0]
    points = np.empty((n, 3), dtype=np.float32)
    side_a = np.empty(n, dtype=np.int64)
    side_b = np.empty(n, dtype=np.int64)
    inside_a = np.empty(n, dtype=np.bool_)
    inside_b = np.empty(n, dtype=np.bool_)
    p = np.empty(3, dtype=np.float64)
    a = np.empty(3, dtype=np.float64)
    b = np.empty(3, dtype=np.float64)
    s = 0
    kept = 0
    for t in range(counts.shape[0]):
        for _ in range(counts[t]):
            keep = True
            fu, fv = _folded(u[s], v[s])
            for axis in range(3):
                p[axis] = _point(origin, e1, e2, t, fu, fv, axis)
                keep = keep and low[axis] <= p[axis] <= high[axis]
            s += 1
            if not keep:
                continue
            for axis in range(3):
                offset = step * normal[t, axis]
                a[axis] = p[axis] + offset
                b[axis] = p[axis] - offset
                points[kept, axis] = np.float32(p[axis])
            side_a[kept], inside_a[kept] = _flat_voxel(a, grid_origin, voxel_size, shape)
            side_b[kept], inside_b[kept] = _flat_voxel(b, grid_origin, voxel_size, shape)
            kept += 1
    return points[:kept], side_a[:kept], inside_a[:kept], side_b[:kept], inside_b[:kept]


def side_voxels(d: Draws, low: FloatArray, high: FloatArray, step: float,
                grid_origin: FloatArray, voxel_size: float, shape: tuple[int, int, int],
                ) -> tuple[npt.NDArray[np.float32], IntArray, BoolArray, IntArray, BoolArray]:
    """The samples within [low, high] (each (3,), metres) and the voxels `step` metres either
    side of each along its triangle's normal.

    Args:
        d: the draws.
        low, high: (3,) the box kept, bounds included.
        step: metres off the surface.
        grid_origin: (3,) the grid's lower corner, metres.
        voxel_size: metres.
        shape: the grid's shape.

    Returns:
        points: (n, 3) float32 kept samples.
        side_a, side_b: (n,) flat voxel indices at +step and -step (clipped into the grid).
        inside_a, inside_b: (n,) bool, whether those voxels lie in the grid.
    """
    return _sides(d.origin, d.edge1, d.edge2, d.normal, d.counts, d.u, d.v,
                  np.asarray(low, dtype=np.float64), np.asarray(high, dtype=np.float64),
                  float(step), np.asarray(grid_origin, dtype=np.float64), float(voxel_size),
                  np.asarray(shape, dtype=np.int64))
