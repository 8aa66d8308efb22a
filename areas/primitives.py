"""Closed (watertight) mesh primitives shared by the built-in area generators.

Every primitive is a closed, consistently wound triangle surface with outward normals and its own
vertices, so a scene is a union of closed components: ray casting, pybullet and the ground truth
(distance based) all treat overlapping components correctly, and each component can be checked
for watertightness on its own. Functions are batched (N primitives per call, vectorised numpy)
because the large areas hold tens of thousands of parts.

The mesh type is `areas.mesh`'s and the single solids (boxes, beams, cylinders, lathes) are
`areas.solids`'; this module builds the assemblies of them (slabs and walls with openings, stairs,
railings, pipe runs) and `Parts`, which collects a generator's parts. It re-exports both, the
generators' one place to import from.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from areas.mesh import FloatArray, IntArray, Mesh, concat
from areas.solids import beams, boxes, cylinders, lathe, oriented_boxes, perpendicular_frame

__all__ = [
    "FloatArray",
    "IntArray",
    "Mesh",
    "Parts",
    "beams",
    "boxes",
    "concat",
    "cylinders",
    "flanges",
    "lathe",
    "oriented_boxes",
    "pipe_run",
    "railing",
    "rects_minus_holes",
    "slab",
    "stairs",
    "wall",
]


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
        u, v = perpendicular_frame(direction)
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
