"""Closed (watertight) solids, batched: boxes, oriented boxes, beams, cylinders and lathes.

Each function meshes N solids per call (vectorised numpy); every solid is a closed,
consistently wound triangle surface with outward normals and its own vertices.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from areas.mesh import FloatArray, IntArray, Mesh

# Unit cube corners (bit 0 -> x, bit 1 -> y, bit 2 -> z) and its 12 triangles, wound
# counter-clockwise seen from outside.
_CUBE_CORNERS = np.array([[(i >> 0) & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)],
                         dtype=np.float64) * 2.0 - 1.0
_CUBE_FACES = np.array([
    [0, 2, 1], [1, 2, 3],  # z = -1
    [4, 5, 6], [5, 7, 6],  # z = +1
    [0, 1, 4], [1, 5, 4],  # y = -1
    [2, 6, 3], [3, 6, 7],  # y = +1
    [0, 4, 2], [2, 4, 6],  # x = -1
    [1, 3, 5], [3, 7, 5],  # x = +1
], dtype=np.int64)


def _batched(vertices: FloatArray, template: IntArray) -> Mesh:
    """(N, K, 3) vertices of N copies of a K-vertex template with faces ``template`` (T, 3)."""
    n, k, _ = vertices.shape
    tris = template[None, :, :] + (np.arange(n) * k)[:, None, None]
    return Mesh(vertices.reshape(-1, 3), tris.reshape(-1, 3))


def boxes(lo: npt.ArrayLike, hi: npt.ArrayLike) -> Mesh:
    """Axis-aligned boxes.

    Args:
        lo: (N, 3) or (3,) lower corners, metres.
        hi: (N, 3) or (3,) upper corners; every side must be longer than zero.
    """
    lo_a = np.atleast_2d(np.asarray(lo, dtype=np.float64))
    hi_a = np.atleast_2d(np.asarray(hi, dtype=np.float64))
    if len(lo_a) == 0:
        return Mesh.empty()
    if np.any(hi_a <= lo_a):
        raise ValueError("box with a side of zero or negative length")
    centre = (lo_a + hi_a) / 2.0
    half = (hi_a - lo_a) / 2.0
    verts = centre[:, None, :] + _CUBE_CORNERS[None, :, :] * half[:, None, :]
    return _batched(verts, _CUBE_FACES)


def oriented_boxes(centre: npt.ArrayLike, axes: npt.ArrayLike, half: npt.ArrayLike) -> Mesh:
    """Boxes with arbitrary orientation.

    Args:
        centre: (N, 3) centres.
        axes: (N, 3, 3) rows are the box's unit axes (right-handed).
        half: (N, 3) half extents along those axes.
    """
    c = np.atleast_2d(np.asarray(centre, dtype=np.float64))
    ax = np.asarray(axes, dtype=np.float64).reshape(-1, 3, 3)
    h = np.atleast_2d(np.asarray(half, dtype=np.float64))
    local = _CUBE_CORNERS[None, :, :] * h[:, None, :]  # (N, 8, 3)
    verts = c[:, None, :] + np.einsum("nki,nij->nkj", local, ax)
    return _batched(verts, _CUBE_FACES)


def beams(p0: npt.ArrayLike, p1: npt.ArrayLike, width: float, depth: float,
          up: tuple[float, float, float] = (0.0, 0.0, 1.0)) -> Mesh:
    """Rectangular bars from ``p0`` (N, 3) to ``p1`` (N, 3), ``width`` across, ``depth`` up."""
    a = np.atleast_2d(np.asarray(p0, dtype=np.float64))
    b = np.atleast_2d(np.asarray(p1, dtype=np.float64))
    x = b - a
    length = np.linalg.norm(x, axis=1)
    x = x / length[:, None]
    up_v = np.broadcast_to(np.asarray(up, dtype=np.float64), x.shape)
    # Bars parallel to ``up`` take another reference direction.
    parallel = np.abs(np.sum(x * up_v, axis=1)) > 0.99
    ref = np.where(parallel[:, None], np.array([1.0, 0.0, 0.0]), up_v)
    y = np.cross(ref, x)
    y /= np.linalg.norm(y, axis=1)[:, None]
    z = np.cross(x, y)
    half = np.stack([length / 2.0, np.full_like(length, width / 2.0),
                     np.full_like(length, depth / 2.0)], axis=1)
    return oriented_boxes((a + b) / 2.0, np.stack([x, y, z], axis=1), half)


def perpendicular_frame(direction: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Two (N, 3) unit vectors u, v with u x v = direction (N, 3, unit)."""
    ref = np.where(np.abs(direction[:, 2:3]) < 0.9, np.array([0.0, 0.0, 1.0]),
                   np.array([1.0, 0.0, 0.0]))
    u = np.cross(ref, direction)
    u /= np.linalg.norm(u, axis=1)[:, None]
    v = np.cross(direction, u)
    return u, v


def _ring_faces(segments: int, rings: int) -> IntArray:
    """Faces of ``rings`` stacked rings of ``segments`` vertices, closed by fan caps."""
    s = segments
    i = np.arange(s)
    j = (i + 1) % s
    faces = []
    for r in range(rings - 1):
        lo, hi = r * s, (r + 1) * s
        faces.append(np.stack([lo + i, lo + j, hi + j], axis=1))
        faces.append(np.stack([lo + i, hi + j, hi + i], axis=1))
    fan = np.arange(1, s - 1)
    faces.append(np.stack([np.zeros_like(fan), fan + 1, fan], axis=1))  # bottom, normal -axis
    top = (rings - 1) * s
    faces.append(np.stack([np.full_like(fan, top), top + fan, top + fan + 1], axis=1))
    return np.concatenate(faces).astype(np.int64)


def cylinders(p0: npt.ArrayLike, p1: npt.ArrayLike, radius: npt.ArrayLike,
              segments: int = 16) -> Mesh:
    """Closed cylinders (prisms of ``segments`` sides) from ``p0`` (N, 3) to ``p1`` (N, 3).

    Args:
        radius: (N,) or scalar, metres.
    """
    a = np.atleast_2d(np.asarray(p0, dtype=np.float64))
    b = np.atleast_2d(np.asarray(p1, dtype=np.float64))
    if len(a) == 0:
        return Mesh.empty()
    r = np.broadcast_to(np.asarray(radius, dtype=np.float64), (len(a),))
    d = b - a
    d = d / np.linalg.norm(d, axis=1)[:, None]
    u, v = perpendicular_frame(d)
    theta = 2.0 * np.pi * np.arange(segments) / segments
    ring = (np.cos(theta)[None, :, None] * u[:, None, :]
            + np.sin(theta)[None, :, None] * v[:, None, :]) * r[:, None, None]  # (N, S, 3)
    verts = np.concatenate([a[:, None, :] + ring, b[:, None, :] + ring], axis=1)
    return _batched(verts, _ring_faces(segments, 2))


def lathe(profile: npt.ArrayLike, centre: npt.ArrayLike, segments: int = 24) -> Mesh:
    """A closed solid of revolution about a vertical axis.

    Args:
        profile: (K, 2) radius and height pairs from bottom to top, radii > 0, heights rising.
        centre: (N, 3) or (3,) base points of the axis; one solid per centre.
        segments: vertices per ring.
    """
    prof = np.asarray(profile, dtype=np.float64)
    c = np.atleast_2d(np.asarray(centre, dtype=np.float64))
    theta = 2.0 * np.pi * np.arange(segments) / segments
    ring = np.stack([
        prof[:, 0:1] * np.cos(theta)[None, :],
        prof[:, 0:1] * np.sin(theta)[None, :],
        np.repeat(prof[:, 1:2], segments, axis=1),
    ], axis=-1).reshape(-1, 3)  # (K * S, 3)
    verts = c[:, None, :] + ring[None, :, :]
    return _batched(verts, _ring_faces(segments, len(prof)))
