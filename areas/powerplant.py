"""POWERPLANT: a fixed 33 x 31 x 26 m crop of a power plant, low poly (about 2000 faces).

A ground slab, four plain buildings of different heights (each roof smaller than a quarter of
the footprint, so none reads as a second level), a turbine hall annex, two chimney stacks to the
top of the volume, a cooling tower (a hyperbolic shell of revolution, closed at its rim), two
storage tanks and a pipe bridge on portal frames. The layout is fixed (seeded only for the
placement jitter of the tanks), like the fixed crop of the original model. Buildings are solid:
the area is explored from outside, as in the paper. A seed other than 0 makes another plant: the
buildings, stacks and tanks get other heights and the whole plan is mirrored (`_varied`).
"""

from __future__ import annotations

import numpy as np

from areas.area import Area, AreaInfo
from areas.assemble import finish_area
from areas.mesh import Mesh
from areas.primitives import Parts, beams, lathe, slab

GENERATOR_VERSION = 1

SIZE = (33.0, 31.0, 26.0)
SEGMENTS = 16


def build_powerplant(seed: int = 0) -> Area:
    """The POWERPLANT area; the same seed gives identical arrays."""
    rng = np.random.default_rng(seed)
    # Seeds other than 0 draw their variations apart, so that seed 0 stays the registered scene.
    layout = np.random.default_rng([seed, 1]) if seed != 0 else None
    X, Y, Z = SIZE
    p = Parts()
    p.add(slab((0.0, 0.0, X, Y), 0.0, 0.15))
    # Buildings: (x0, y0, x1, y1, height).
    buildings = [(2.0, 2.0, 14.0, 13.0, 14.0), (2.0, 16.0, 10.0, 28.0, 9.0),
                 (17.0, 2.0, 26.0, 9.0, 6.0), (22.0, 22.0, 31.0, 29.0, 11.0)]
    tank_h = 6.0
    if layout is not None:
        buildings = [(x0, y0, x1, y1, round(float(layout.uniform(4.0, 18.0)), 2))
                     for x0, y0, x1, y1, _ in buildings]
        tank_h = round(float(layout.uniform(3.0, 9.0)), 2)
    for x0, y0, x1, y1, h in buildings:
        p.box((x0, y0, 0.15), (x1, y1, h))
        # A roof parapet and a roof-top unit.
        p.box((x0 - 0.1, y0 - 0.1, h), (x1 + 0.1, y1 + 0.1, h + 0.4))
        p.box((x0 + 1.0, y0 + 1.0, h + 0.4), (x0 + 3.0, y0 + 2.5, h + 1.6))
    # Turbine hall annex with a pitched roof (an oriented box ridge).
    p.box((10.0, 13.0, 0.15), (14.0, 16.0, 7.0))
    p.add(beams([(10.0, 14.5, 7.0)], [(14.0, 14.5, 7.0)], 2.2, 1.0))
    # Chimney stacks to the top of the volume, with a ring platform.
    for sx, sy in ((17.0, 14.5), (20.0, 14.5)):
        p.add(lathe([[1.1, 0.15], [0.9, 12.0], [0.7, Z]], (sx, sy, 0.0), SEGMENTS))
        p.cylinder((sx, sy, 16.0), (sx, sy, 16.3), 1.5, SEGMENTS)
    # Cooling tower: a hyperbolic shell, closed (the model's interior is not explored).
    tower = [[5.0, 0.15], [4.0, 6.0], [3.2, 12.0], [3.1, 15.0], [3.5, 19.0], [3.9, 21.0]]
    p.add(lathe(tower, (26.5, 15.5, 0.0), SEGMENTS * 2))
    # Storage tanks.
    for tx, ty in ((5.0 + rng.uniform(-0.3, 0.3), 30.0 - 1.4), (14.0, 26.0)):
        p.add(lathe([[1.6, 0.15], [1.6, tank_h], [1.0, tank_h + 0.8], [0.3, tank_h + 1.0]],
                    (tx, ty, 0.0), SEGMENTS))
    # Pipe bridge from the main building to the stacks and tower on portal frames.
    for bx in (15.0, 19.5, 23.0):
        for by in (10.5, 12.0):
            p.box((bx - 0.2, by - 0.2, 0.15), (bx + 0.2, by + 0.2, 8.0))
        p.box((bx - 0.25, 10.2, 8.0), (bx + 0.25, 12.3, 8.4))
    for k, by in enumerate((10.8, 11.4)):
        p.cylinder((14.0, by, 8.7 + 0.2 * k), (24.0, by, 8.7 + 0.2 * k), 0.3, SEGMENTS)

    mesh, start = p.build(), (16.0, 20.0, 2.0)
    if layout is not None:
        mesh, start = _mirrored(mesh, start, int(layout.integers(1, 4)))
    return finish_area(
        name="powerplant", mesh=mesh, bounds_min=np.zeros(3), bounds_max=np.array(SIZE),
        start=start, yaw=0.0, plateau_s=1800.0, voxel_size=0.2,
        info=AreaInfo(title="POWERPLANT", rooms=None, levels=1, complexity="low", indoor=False),
        generator_version=GENERATOR_VERSION, seed=seed,
    )


def _mirrored(mesh: Mesh, start: tuple[float, float, float],
              axes: int) -> tuple[Mesh, tuple[float, float, float]]:
    """The plan mirrored across x (bit 0 of ``axes``) and y (bit 1), within the crop."""
    vertices, triangles = mesh.vertices.copy(), mesh.triangles
    point = list(start)
    flips = 0
    for axis in (0, 1):
        if axes >> axis & 1:
            vertices[:, axis] = SIZE[axis] - vertices[:, axis]
            point[axis] = SIZE[axis] - point[axis]
            flips += 1
    if flips % 2:  # a reflection turns the faces inside out: keep their winding outward
        triangles = triangles[:, ::-1].copy()
    return Mesh(vertices, triangles), (point[0], point[1], point[2])
