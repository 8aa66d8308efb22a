"""WAREHOUSE: a 40 x 20 x 12 m hall with pallet racks, a large empty centre and a mezzanine.

Ground level: two blocks of pallet racks (7 m high, four beam levels, loaded pallets) at both
ends, with 2.8 m aisles, and an empty central space. A mezzanine 5 m up runs along the back wall
(40 x 7 m) on columns, reached by a straight stair and open to the hall over a 1.1 m railing, so
it can be flown onto anywhere along its 40 m front. Roof trusses, sprinkler lines with heads,
hanging lights, and shelving on the mezzanine complete it.
"""

from __future__ import annotations

import itertools

import numpy as np

from areas.area import Area, AreaInfo
from areas.assemble import finish_area
from areas.equipment import column
from areas.primitives import Parts, beams, lathe, railing, slab, stairs, wall

GENERATOR_VERSION = 1

SIZE = (40.0, 20.0, 12.0)
OUTER = 0.25
MEZZ_Z = 5.0
MEZZ_Y = 12.8  # front edge of the mezzanine
RACK_H = 7.0
SEGMENTS = 64


def _pallet(p: Parts, x: float, y: float, z: float, rng: np.random.Generator) -> None:
    """A 1.2 x 1.0 m pallet at (x, y) on height z, loaded with a stack of cartons."""
    for dy in (-0.45, 0.0, 0.45):
        p.box((x - 0.6, y + dy - 0.05, z), (x + 0.6, y + dy + 0.05, z + 0.1))
    for dx in np.linspace(-0.55, 0.55, 5):
        p.box((x + dx - 0.05, y - 0.5, z + 0.1), (x + dx + 0.05, y + 0.5, z + 0.13))
    layers = int(rng.integers(1, 4))
    for k in range(layers):
        for cx in (-0.3, 0.3):
            for cy in (-0.25, 0.25):
                if rng.random() < 0.85:
                    zb = z + 0.13 + k * 0.36
                    p.box((x + cx - 0.29, y + cy - 0.24, zb), (x + cx + 0.29, y + cy + 0.24,
                                                               zb + 0.35))


def _rack_row(p: Parts, x0: float, x1: float, y: float, rng: np.random.Generator) -> None:
    """A pallet rack row along x, 1.1 m deep, bays of 2.7 m, four beam levels."""
    bays = int((x1 - x0) // 2.7)
    xs = x0 + np.arange(bays + 1) * 2.7
    for xu in xs:
        for dy in (-0.5, 0.5):
            p.box((xu - 0.05, y + dy - 0.05, 0.15), (xu + 0.05, y + dy + 0.05, RACK_H))
        # Diagonal bracing between the front and back uprights.
        for z0 in np.arange(0.5, RACK_H - 1.0, 1.5):
            p.add(beams([(xu, y - 0.45, z0)], [(xu, y + 0.45, z0 + 1.2)], 0.03, 0.03))
    for level in range(4):
        zb = 0.15 + 0.2 + level * 1.7
        for dy in (-0.5, 0.5):
            p.box((xs[0] - 0.05, y + dy - 0.06, zb), (xs[-1] + 0.05, y + dy + 0.06, zb + 0.12))
        for a, _b in itertools.pairwise(xs):
            for k in range(2):
                if rng.random() < 0.8:
                    _pallet(p, a + 0.1 + 0.65 + k * 1.25, y, zb + 0.12, rng)


def build_warehouse(seed: int = 0) -> Area:
    """The WAREHOUSE area; the same seed gives identical arrays."""
    rng = np.random.default_rng(seed)
    X, Y, Z = SIZE
    p = Parts()
    p.add(slab((0.0, 0.0, X, Y), 0.0, 0.15), slab((0.0, 0.0, X, Y), Z - 0.2, Z))
    for axis, at in ((0, OUTER / 2), (0, Y - OUTER / 2), (1, OUTER / 2), (1, X - OUTER / 2)):
        p.add(wall(axis, 0.0, X if axis == 0 else Y, at, OUTER, 0.0, Z))
    # Loading doors (closed shutters, slightly recessed) on the front wall.
    for dx in (8.0, 20.0, 32.0):
        p.box((dx - 2.0, OUTER, 0.15), (dx + 2.0, OUTER + 0.08, 4.5))

    # Pallet racks: two blocks at the ends, the centre x in [14, 28] left empty.
    for xa, xb in ((1.0, 12.0), (29.0, 39.4)):
        for y in (1.2, 4.8, 5.9, 9.5):
            _rack_row(p, xa, xb, y, rng)

    # Mezzanine: slab on columns and beams, railing along the front with the stair landing open.
    p.add(slab((OUTER, MEZZ_Y, X - OUTER, Y - OUTER), MEZZ_Z - 0.2, MEZZ_Z))
    p.add(beams([(OUTER, MEZZ_Y + 0.15, MEZZ_Z - 0.45)], [(X - OUTER, MEZZ_Y + 0.15,
                                                            MEZZ_Z - 0.45)], 0.2, 0.5))
    for cx in np.arange(4.0, X - 1.0, 4.0):
        column(p, float(cx), MEZZ_Y + 0.2, 0.15, MEZZ_Z - 0.7, 0.3)
    stair_x0 = 15.0
    flight = stairs((stair_x0, MEZZ_Y - 0.6, 0.15), 0, 1.0, 1.1, MEZZ_Z - 0.15, run=0.28)
    p.add(flight)
    stair_end = stair_x0 + round((MEZZ_Z - 0.15) / 0.18) * 0.28
    p.add(railing([(OUTER + 0.1, MEZZ_Y + 0.05, MEZZ_Z), (stair_end - 1.5, MEZZ_Y + 0.05, MEZZ_Z)]))
    p.add(railing([(stair_end + 0.5, MEZZ_Y + 0.05, MEZZ_Z),
                   (X - OUTER - 0.1, MEZZ_Y + 0.05, MEZZ_Z)]))
    # Shelving units on the mezzanine against the back wall, every other 2 m.
    for sx in np.arange(1.0, X - 2.0, 4.0):
        y0, y1 = Y - OUTER - 0.6, Y - OUTER - 0.05
        for ux in (sx, sx + 1.95):
            p.box((ux, y0, MEZZ_Z), (ux + 0.05, y1, MEZZ_Z + 2.2))
        for k in range(5):
            zb = MEZZ_Z + 0.1 + k * 0.5
            p.box((sx, y0, zb), (sx + 2.0, y1, zb + 0.03))
            for bx in np.arange(sx + 0.1, sx + 1.8, 0.45):
                if rng.random() < 0.6:
                    p.box((bx, y0 + 0.05, zb + 0.03), (bx + 0.4, y1 - 0.05, zb + 0.33))

    # Roof: trusses every 5 m across y, purlins along x, sprinkler lines with heads, lights.
    top = Z - 0.2
    for tx in np.arange(2.5, X, 5.0):
        p.add(beams([(tx, OUTER, top - 0.1)], [(tx, Y - OUTER, top - 0.1)], 0.15, 0.2))
        p.add(beams([(tx, OUTER, top - 1.3)], [(tx, Y - OUTER, top - 1.3)], 0.15, 0.15))
        ys = np.linspace(OUTER, Y - OUTER, 9)
        for k, (a, b) in enumerate(itertools.pairwise(ys)):
            z0, z1 = (top - 1.3, top - 0.1) if k % 2 == 0 else (top - 0.1, top - 1.3)
            p.add(beams([(tx, a, z0)], [(tx, b, z1)], 0.08, 0.08))
    for py in np.arange(2.0, Y - 1.0, 3.0):
        p.add(beams([(OUTER, py, top - 0.05)], [(X - OUTER, py, top - 0.05)], 0.1, 0.1))
    heads: list[tuple[float, float]] = []
    for sy in np.arange(3.5, Y - 1.0, 4.0):
        p.cylinder((OUTER, sy, top - 1.6), (X - OUTER, sy, top - 1.6), 0.05, SEGMENTS)
        for hx in np.arange(1.5, X - 1.0, 1.5):
            p.cylinder((hx, sy, top - 1.6), (hx, sy, top - 1.85), 0.015, SEGMENTS // 3)
            heads.append((hx, sy))
        for lx in np.arange(2.0, X - 1.0, 2.5):
            p.cylinder((lx, sy + 1.0, top - 1.3), (lx, sy + 1.0, top - 2.3), 0.01, 6)
            p.add(lathe([[0.05, 0.0], [0.35, 0.25], [0.3, 0.35], [0.08, 0.4]],
                        (lx, sy + 1.0, top - 2.7), SEGMENTS * 2))
    del heads

    return finish_area(
        name="warehouse", mesh=p.build(), bounds_min=np.zeros(3), bounds_max=np.array(SIZE),
        start=(21.0, 7.5, 1.5), yaw=0.0, plateau_s=900.0, voxel_size=0.2,
        info=AreaInfo(title="WAREHOUSE", rooms=1, levels=2, complexity="high", indoor=True),
        generator_version=GENERATOR_VERSION, seed=seed,
    )
