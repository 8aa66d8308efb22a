"""Closed (watertight) mesh primitives shared by the built-in area generators.

Every primitive is a closed, consistently wound triangle surface with outward normals and its own
vertices, so a scene is a union of closed components: ray casting, pybullet and the ground truth
(distance based) all treat overlapping components correctly, and each component can be checked
for watertightness on its own. Functions are batched (N primitives per call, vectorised numpy)
because the large areas hold tens of thousands of parts.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

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


@dataclass
class Mesh:
    """A triangle mesh.

    Attributes:
        vertices: (V, 3) float64 metres.
        triangles: (F, 3) int64 indices into ``vertices``.
    """

    vertices: FloatArray
    triangles: IntArray

    @staticmethod
    def empty() -> Mesh:
        return Mesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64))


@dataclass
class MeshBuilder:
    """Collects meshes and concatenates them once at the end (cheaper than growing arrays)."""

    parts: list[Mesh] = field(default_factory=list)

    def add(self, *meshes: Mesh) -> None:
        self.parts.extend(m for m in meshes if len(m.triangles))

    def build(self) -> Mesh:
        return concat(self.parts)


def concat(meshes: Sequence[Mesh]) -> Mesh:
    """One mesh holding all ``meshes``; vertex indices are shifted, nothing is merged."""
    if not meshes:
        return Mesh.empty()
    offsets = np.cumsum([0] + [len(m.vertices) for m in meshes[:-1]])
    return Mesh(
        np.concatenate([m.vertices for m in meshes]),
        np.concatenate([m.triangles + off for m, off in zip(meshes, offsets, strict=True)]),
    )


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


def _frame(direction: FloatArray) -> tuple[FloatArray, FloatArray]:
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
    u, v = _frame(d)
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


def rects_minus_holes(
    outer: tuple[float, float, float, float],
    holes: Sequence[tuple[float, float, float, float]],
) -> list[tuple[float, float, float, float]]:
    """Cover a rectangle minus rectangular holes with disjoint rectangles.

    Rectangles are ``(u0, v0, u1, v1)``. The plane is cut on every hole edge; free cells of one
    row are merged into runs, so a wall with one door gives three or four pieces.
    """
    u0, v0, u1, v1 = outer
    us = sorted({u0, u1, *(min(max(h[0], u0), u1) for h in holes),
                 *(min(max(h[2], u0), u1) for h in holes)})
    vs = sorted({v0, v1, *(min(max(h[1], v0), v1) for h in holes),
                 *(min(max(h[3], v0), v1) for h in holes)})
    out: list[tuple[float, float, float, float]] = []
    for b0, b1 in itertools.pairwise(vs):
        run: float | None = None
        for a0, a1 in itertools.pairwise(us):
            cu, cv = (a0 + a1) / 2.0, (b0 + b1) / 2.0
            free = not any(h[0] < cu < h[2] and h[1] < cv < h[3] for h in holes)
            if free and run is None:
                run = a0
            if not free and run is not None:
                out.append((run, b0, a0, b1))
                run = None
        if run is not None:
            out.append((run, b0, us[-1], b1))
    return out


def slab(outer: tuple[float, float, float, float], z0: float, z1: float,
         holes: Sequence[tuple[float, float, float, float]] = ()) -> Mesh:
    """A horizontal slab from ``z0`` to ``z1`` over ``outer`` (x0, y0, x1, y1) minus ``holes``."""
    pieces = np.array(rects_minus_holes(outer, holes), dtype=np.float64).reshape(-1, 4)
    lo = np.column_stack([pieces[:, 0], pieces[:, 1], np.full(len(pieces), z0)])
    hi = np.column_stack([pieces[:, 2], pieces[:, 3], np.full(len(pieces), z1)])
    return boxes(lo, hi)


def wall(axis: int, start: float, end: float, at: float, thickness: float, z0: float, z1: float,
         openings: Sequence[tuple[float, float, float, float]] = ()) -> Mesh:
    """A vertical wall running along ``axis`` (0: x, 1: y) from ``start`` to ``end``.

    Args:
        at: the wall's centre-line coordinate on the other horizontal axis.
        openings: doors and windows as ``(s0, z0, s1, z1)``: along-wall span and height span.
    """
    pieces = np.array(rects_minus_holes((start, z0, end, z1), openings),
                      dtype=np.float64).reshape(-1, 4)
    n = len(pieces)
    across = np.column_stack([np.full(n, at - thickness / 2.0), np.full(n, at + thickness / 2.0)])
    lo = np.zeros((n, 3))
    hi = np.zeros((n, 3))
    lo[:, axis], hi[:, axis] = pieces[:, 0], pieces[:, 2]
    lo[:, 1 - axis], hi[:, 1 - axis] = across[:, 0], across[:, 1]
    lo[:, 2], hi[:, 2] = pieces[:, 1], pieces[:, 3]
    return boxes(lo, hi)


def stairs(start: npt.ArrayLike, direction: int, sign: float, width: float, rise: float,
           run: float = 0.3, tread: float = 0.05) -> Mesh:
    """An open straight flight: floating treads and two inclined stringers.

    Args:
        start: (3,) centre of the foot of the flight on the lower floor.
        direction: horizontal axis the flight climbs along (0: x, 1: y).
        sign: +1 or -1, which way along that axis.
        width: flight width across, metres.
        rise: total height climbed; steps of about 0.18 m.
    """
    s = np.asarray(start, dtype=np.float64)
    n = max(2, round(rise / 0.18))
    step_h = rise / n
    k = np.arange(1, n + 1)
    along = s[direction] + sign * (k - 0.5) * run
    across = 1 - direction
    centre = np.zeros((n, 3))
    centre[:, direction] = along
    centre[:, across] = s[across]
    centre[:, 2] = s[2] + k * step_h - tread / 2.0
    half = np.zeros((n, 3))
    half[:, direction] = run / 2.0
    half[:, across] = width / 2.0 - 0.06
    half[:, 2] = tread / 2.0
    treads = boxes(centre - half, centre + half)
    length = n * run
    p0 = np.tile(s, (2, 1))
    p1 = p0.copy()
    p1[:, direction] += sign * length
    p1[:, 2] += rise
    off = np.array([-1.0, 1.0]) * (width / 2.0 - 0.03)
    p0[:, across] += off
    p1[:, across] += off
    stringers = beams(p0, p1, 0.06, 0.2)
    return concat([treads, stringers])


def railing(points: npt.ArrayLike, height: float = 1.1, post_spacing: float = 1.5,
            radius: float = 0.025, segments: int = 8) -> Mesh:
    """A tubular railing along a polyline (M, 3) of floor points: posts, a top and a mid rail."""
    pts = np.asarray(points, dtype=np.float64)
    posts: list[FloatArray] = []
    for a, b in itertools.pairwise(pts):
        n = max(1, int(np.ceil(np.linalg.norm(b - a) / post_spacing)))
        t = np.linspace(0.0, 1.0, n + 1)[:-1]
        posts.append(a[None, :] + t[:, None] * (b - a)[None, :])
    posts.append(pts[-1:])
    base = np.concatenate(posts)
    up = np.array([0.0, 0.0, 1.0])
    parts = [cylinders(base, base + height * up, radius, segments)]
    for h in (height, height / 2.0):
        parts.append(cylinders(pts[:-1] + h * up, pts[1:] + h * up, radius, segments))
    return concat(parts)


def pipe_run(points: npt.ArrayLike, radius: float, segments: int = 16,
             flange_every: float = 0.0, bolts: int = 0) -> Mesh:
    """A pipe along a polyline (M, 3): one cylinder per leg, a sphere-like joint at each bend,
    and optional flanges (with ``bolts`` bolt heads each) every ``flange_every`` metres."""
    pts = np.asarray(points, dtype=np.float64)
    parts = [cylinders(pts[:-1], pts[1:], radius, segments)]
    if len(pts) > 2:
        # A short fat cylinder hides the seam at every bend, like an elbow fitting.
        bend = pts[1:-1]
        d = pts[2:] - pts[:-2]
        d /= np.linalg.norm(d, axis=1)[:, None]
        parts.append(cylinders(bend - d * radius * 1.3, bend + d * radius * 1.3, radius * 1.15,
                               segments))
    if flange_every > 0.0:
        centres: list[FloatArray] = []
        dirs: list[FloatArray] = []
        for a, b in itertools.pairwise(pts):
            length = float(np.linalg.norm(b - a))
            n = int(length // flange_every)
            if n < 1:
                continue
            d = (b - a) / length
            t = (np.arange(1, n + 1) * flange_every)[: n if n * flange_every < length else n - 1]
            centres.append(a[None, :] + t[:, None] * d[None, :])
            dirs.append(np.tile(d, (len(t), 1)))
        if centres:
            parts.append(flanges(np.concatenate(centres), np.concatenate(dirs), radius, segments,
                                 bolts))
    return concat(parts)


def flanges(centre: FloatArray, direction: FloatArray, radius: float, segments: int,
            bolts: int) -> Mesh:
    """Pipe flanges: a disc of 1.6 ``radius`` at each (N, 3) centre across (N, 3) ``direction``
    unit vectors, with ``bolts`` small bolt cylinders through its rim."""
    thick = max(0.02, 0.25 * radius)
    parts = [cylinders(centre - direction * thick / 2.0, centre + direction * thick / 2.0,
                       radius * 1.6, segments)]
    if bolts:
        u, v = _frame(direction)
        ang = 2.0 * np.pi * (np.arange(bolts) + 0.5) / bolts
        rb = radius * 1.35
        off = (np.cos(ang)[None, :, None] * u[:, None, :]
               + np.sin(ang)[None, :, None] * v[:, None, :]) * rb
        pos = (centre[:, None, :] + off).reshape(-1, 3)
        d = np.repeat(direction, bolts, axis=0)
        parts.append(cylinders(pos - d * thick, pos + d * thick, max(0.008, 0.1 * radius), 6))
    return concat(parts)


@dataclass
class Parts:
    """Accumulates primitives one by one and builds them in a few batched calls.

    Generators place parts in Python loops; collecting their parameters and meshing them together
    keeps the per-part cost at a list append.
    """

    box_lo: list[tuple[float, float, float]] = field(default_factory=list)
    box_hi: list[tuple[float, float, float]] = field(default_factory=list)
    cyl: dict[int, list[tuple[float, ...]]] = field(default_factory=dict)
    meshes: list[Mesh] = field(default_factory=list)

    def box(self, lo: npt.ArrayLike, hi: npt.ArrayLike) -> None:
        """An axis-aligned box from ``lo`` (3,) to ``hi`` (3,)."""
        a, b = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
        self.box_lo.append((float(a[0]), float(a[1]), float(a[2])))
        self.box_hi.append((float(b[0]), float(b[1]), float(b[2])))

    def box_at(self, centre: npt.ArrayLike, size: npt.ArrayLike) -> None:
        """An axis-aligned box of ``size`` (3,) around ``centre`` (3,)."""
        c, s = np.asarray(centre, dtype=np.float64), np.asarray(size, dtype=np.float64)
        self.box(c - s / 2.0, c + s / 2.0)

    def cylinder(self, p0: npt.ArrayLike, p1: npt.ArrayLike, radius: float,
                 segments: int = 16) -> None:
        """A closed cylinder from ``p0`` (3,) to ``p1`` (3,)."""
        a, b = np.asarray(p0, dtype=np.float64), np.asarray(p1, dtype=np.float64)
        self.cyl.setdefault(segments, []).append(
            (float(a[0]), float(a[1]), float(a[2]), float(b[0]), float(b[1]), float(b[2]),
             float(radius)))

    def add(self, *meshes: Mesh) -> None:
        """Ready-made meshes (stairs, railings, lathes ...)."""
        self.meshes.extend(m for m in meshes if len(m.triangles))

    def build(self) -> Mesh:
        parts = list(self.meshes)
        if self.box_lo:
            parts.append(boxes(np.array(self.box_lo), np.array(self.box_hi)))
        for segments, rows in sorted(self.cyl.items()):
            a = np.array(rows)
            parts.append(cylinders(a[:, 0:3], a[:, 3:6], a[:, 6], segments))
        return concat(parts)
