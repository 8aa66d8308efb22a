"""FACILITY A, B and C: industrial halls full of tanks, pumps, cabinets, pipes and ducts.

One generator, three configurations. The building (``size``) has one or two storeys; each storey
is split along x into halls joined by 2 m wide openings. A main aisle (``aisle`` wide) runs along
x through every hall; equipment stands in the two strips beside it, in bays separated by cross
passages of at least 1.2 m; strips deeper than 6 m hold two rows of equipment. Pipe racks run
along x under the ceiling over both strips, with drops to the equipment, flanges and bolts (the
detail that makes real plant models heavy); a duct runs over the aisle. Two storeys are joined by
a stairwell (stairs beside a shaft at least 1.35 m wide) and an open hatch in the upper slab.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from areas.area import Area, AreaInfo
from areas.assemble import finish_area
from areas.equipment import cabinet, column, duct, pipe, pump, tank, valve
from areas.primitives import Parts, railing, slab, stairs, wall

GENERATOR_VERSION = 1

OUTER = 0.2
INNER = 0.15
SLAB = 0.2
OPENING_W = 2.0
Rect = tuple[float, float, float, float]


@dataclass(frozen=True)
class FacilityConfig:
    """One facility.

    Attributes:
        size: (x, y, z) bounding volume, metres.
        halls: halls per storey, bottom storey first.
        aisle: main aisle width, metres.
        bay: bay pitch along x, metres.
        pipes: pipes per rack (two racks per hall).
        segments: sides of round parts.
        flange_every: flange spacing on pipes, metres.
        bolts: bolts per flange.
    """

    name: str
    title: str
    size: tuple[float, float, float]
    halls: tuple[int, ...]
    aisle: float
    bay: float
    pipes: int
    segments: int
    flange_every: float
    bolts: int
    plateau_s: float


def _overlaps(rect: Rect, others: list[Rect]) -> bool:
    return any(rect[0] < o[2] and o[0] < rect[2] and rect[1] < o[3] and o[1] < rect[3]
               for o in others)


def _equipment(p: Parts, cfg: FacilityConfig, x: float, y0: float, y1: float, floor: float,
               ceil: float, pipe_z: float, rack_y: float, rng: np.random.Generator) -> None:
    """One bay: the strip from y0 to y1 (one side of the aisle), centred at x along the hall."""
    seg = cfg.segments
    depth = y1 - y0
    yc = (y0 + y1) / 2.0
    kind = rng.choice(["tank", "pumps", "cabinets", "vessel"], p=[0.35, 0.25, 0.2, 0.2])
    head = ceil - floor
    nozzle: tuple[float, float, float]
    if kind == "tank":
        r = float(min(0.45 * depth, (cfg.bay - 1.2) / 2.0, rng.uniform(0.55, 1.0)))
        h = float(min(head - 1.4, rng.uniform(1.6, 3.5)))
        tank(p, x, yc, floor, r, h, seg)
        nozzle = (x, yc, floor + h + 0.4 * r)
    elif kind == "pumps":
        for dy in (-0.5, 0.5):
            pump(p, x, yc + dy * min(depth - 0.7, 1.4), floor, 0, seg)
        nozzle = (x + 0.32, yc, floor + 1.1)
    elif kind == "cabinets":
        width = min(cfg.bay - 1.2, 2.4)
        wall_side = y0 if abs(y0 - rack_y) > abs(y1 - rack_y) else y1
        sign = 1.0 if wall_side == y0 else -1.0
        lo_y, hi_y = sorted((wall_side, wall_side + sign * 0.6))
        for k in range(3):
            xs = x - width / 2.0 + k * width / 3.0
            cabinet(p, (xs + 0.01, lo_y, floor), (xs + width / 3.0 - 0.01, hi_y, floor + 2.0), 1,
                    sign)
        nozzle = (x, (lo_y + hi_y) / 2.0, floor + 2.0)
    else:
        # A horizontal vessel on two saddles, along x.
        r = float(min(0.4 * depth, 0.8, (head - 1.4) / 2.4))
        length = cfg.bay - 1.3
        zc = floor + 0.3 + r
        for sx in (-0.3, 0.3):
            p.box((x + sx * length - 0.1, yc - 0.7 * r, floor), (x + sx * length + 0.1,
                                                                 yc + 0.7 * r, zc))
        p.cylinder((x - length / 2.0, yc, zc), (x + length / 2.0, yc, zc), r, seg)
        for ex in (-1.0, 1.0):
            p.cylinder((x + ex * length / 2.0, yc, zc), (x + ex * (length / 2.0 + 0.12), yc, zc),
                       r * 0.9, seg)
        nozzle = (x, yc, zc + r)
    # A drop from the rack to the equipment, with a valve.
    r_pipe = 0.05
    top = (nozzle[0], rack_y, pipe_z)
    mid = (nozzle[0], nozzle[1], pipe_z)
    pipe(p, [top, mid, (nozzle[0], nozzle[1], nozzle[2] + 0.05)], r_pipe, max(8, seg // 2),
         cfg.flange_every, cfg.bolts)
    valve(p, np.array([nozzle[0], nozzle[1], (pipe_z + nozzle[2]) / 2.0]),
          np.array([0.0, 0.0, 1.0]), r_pipe, max(8, seg // 2))


def _hall(p: Parts, cfg: FacilityConfig, x0: float, x1: float, floor: float, ceil: float,
          keep_out: list[Rect], rng: np.random.Generator) -> None:
    """Equipment, racks, pipes and a duct of the hall from x0 to x1."""
    Y = cfg.size[1]
    seg = cfg.segments
    ya, yb = Y / 2.0 - cfg.aisle / 2.0, Y / 2.0 + cfg.aisle / 2.0
    strips = ((OUTER + 0.1, ya), (yb, Y - OUTER - 0.1))
    pipe_z0 = ceil - 0.35
    n_bays = max(1, int((x1 - x0 - 0.6) // cfg.bay))
    xs = x0 + (x1 - x0) / 2.0 + (np.arange(n_bays) - (n_bays - 1) / 2.0) * cfg.bay
    for s0, s1 in strips:
        # The rack sits over the strip edge next to the aisle.
        rack_y = s1 - 0.3 if s1 == ya else s0 + 0.3
        # Deep strips hold two rows of equipment with a 1.4 m passage between them.
        rows = [(s0, s1)] if s1 - s0 < 6.0 else [(s0, (s0 + s1) / 2.0 - 0.7),
                                                 ((s0 + s1) / 2.0 + 0.7, s1)]
        for r0, r1 in rows:
            for x in xs:
                if _overlaps((x - cfg.bay / 2.0, r0, x + cfg.bay / 2.0, r1), keep_out):
                    continue
                _equipment(p, cfg, float(x), r0, r1, floor, ceil, pipe_z0 - 0.3, rack_y, rng)
        # Rack posts every 3 m and the pipes along it, at two heights.
        for px in np.arange(x0 + 0.5, x1 - 0.4, 3.0):
            column(p, float(px), rack_y, floor, ceil, 0.16)
        for k in range(cfg.pipes):
            yk = rack_y + (k - (cfg.pipes - 1) / 2.0) * 0.3 * (1 if s0 < ya else -1)
            yk = min(max(yk, OUTER + 0.2), Y - OUTER - 0.2)
            zk = pipe_z0 - 0.3 * (k % 2)
            radius = float(rng.choice([0.04, 0.06, 0.08, 0.1]))
            pipe(p, [(x0 + 0.1, yk, zk), (x1 - 0.1, yk, zk)], radius, seg, cfg.flange_every,
                 cfg.bolts)
    duct(p, x0 + 0.1, x1 - 0.1, Y / 2.0, ceil - 0.25, min(0.8, cfg.aisle - 0.4), 0.4)
    # Cable trays along both walls.
    for yw in (OUTER + 0.25, Y - OUTER - 0.25):
        p.box((x0 + 0.1, yw - 0.15, ceil - 0.9), (x1 - 0.1, yw + 0.15, ceil - 0.85))
    del seg


def build_facility(cfg: FacilityConfig, seed: int = 0) -> Area:
    """A facility per ``cfg``; the same seed gives identical arrays."""
    rng = np.random.default_rng(seed)
    X, Y, Z = cfg.size
    n_levels = len(cfg.halls)
    storey = Z / n_levels
    p = Parts()
    p.add(slab((0.0, 0.0, X, Y), 0.0, 0.15), slab((0.0, 0.0, X, Y), Z - 0.15, Z))
    for axis, at in ((0, OUTER / 2), (0, Y - OUTER / 2), (1, OUTER / 2), (1, X - OUTER / 2)):
        p.add(wall(axis, 0.0, X if axis == 0 else Y, at, OUTER, 0.0, Z))
    # The stairwell sits in the first hall by the y = 0 wall, the hatch in the last hall.
    stair_hole: Rect = (0.6, OUTER + 0.05, 5.4, OUTER + 2.45)
    hatch: Rect = (X - 4.0, Y / 2.0 + cfg.aisle / 2.0 + 0.2, X - 1.0, Y / 2.0 + cfg.aisle / 2.0
                   + 2.6)
    holes = [stair_hole, hatch] if n_levels > 1 else []
    for lvl in range(1, n_levels):
        p.add(slab((0.0, 0.0, X, Y), lvl * storey - SLAB / 2, lvl * storey + SLAB / 2, holes))
    keep_out = [(h[0] - 0.8, h[1] - 0.8, h[2] + 0.8, h[3] + 0.8) for h in holes]

    for lvl, halls in enumerate(cfg.halls):
        floor = 0.15 if lvl == 0 else lvl * storey + SLAB / 2
        ceil = Z - 0.15 if lvl == n_levels - 1 else (lvl + 1) * storey - SLAB / 2
        edges = np.linspace(0.0, X, halls + 1)
        for xw in edges[1:-1]:
            # Openings at the aisle and at one side strip, 2 m wide.
            door_h = min(2.6, ceil - floor - 0.3)
            spots = (Y / 2.0, OUTER + 1.4 if lvl % 2 == 0 else Y - OUTER - 1.4)
            p.add(wall(1, 0.0, Y, float(xw), INNER, floor, ceil,
                       [(s - OPENING_W / 2, floor, s + OPENING_W / 2, floor + door_h)
                        for s in spots]))
        hall_keep = keep_out + [(xw - 1.0, s - 1.2, xw + 1.0, s + 1.2) for xw in edges[1:-1]
                                for s in (OUTER + 1.4, Y - OUTER - 1.4)]
        for h0, h1 in itertools.pairwise(edges):
            lo = h0 + (OUTER if h0 == 0.0 else INNER / 2)
            hi = h1 - (OUTER if h1 == X else INNER / 2)
            _hall(p, cfg, float(lo), float(hi), floor, ceil, hall_keep, rng)
        if lvl + 1 < n_levels:
            top = (lvl + 1) * storey + SLAB / 2
            sx0, sy0, sx1, sy1 = stair_hole
            length = sx1 - sx0 - 0.2
            n_steps = max(2, round((top - floor) / 0.18))
            p.add(stairs((sx0 + 0.1, sy0 + 0.55, floor), 0, 1.0, 1.0, top - floor,
                         run=length / n_steps))
            p.add(railing([(sx0, sy1 + 0.05, top), (sx1, sy1 + 0.05, top)]))
            hx0, hy0, _hx1, hy1 = hatch
            p.add(railing([(hx0 - 0.05, hy0, top), (hx0 - 0.05, hy1, top)]))

    return finish_area(
        name=cfg.name, mesh=p.build(), bounds_min=np.zeros(3), bounds_max=np.array(cfg.size),
        start=(1.5, Y / 2.0, 1.3), yaw=0.0, plateau_s=cfg.plateau_s, voxel_size=0.1,
        info=AreaInfo(title=cfg.title, rooms=sum(cfg.halls), levels=n_levels, complexity="high",
                      indoor=True),
        generator_version=GENERATOR_VERSION, seed=seed,
    )


FACILITY_A = FacilityConfig(
    name="facility-a", title="FACILITY A", size=(12.0, 14.0, 6.0), halls=(1,), aisle=2.0,
    bay=3.2, pipes=6, segments=48, flange_every=0.5, bolts=8, plateau_s=700.0,
)
FACILITY_B = FacilityConfig(
    name="facility-b", title="FACILITY B", size=(19.0, 17.0, 4.6), halls=(2,), aisle=1.8,
    bay=3.0, pipes=10, segments=64, flange_every=0.5, bolts=12, plateau_s=750.0,
)
FACILITY_C = FacilityConfig(
    name="facility-c", title="FACILITY C", size=(38.0, 22.0, 6.0), halls=(3, 2), aisle=2.0,
    bay=3.4, pipes=6, segments=32, flange_every=0.6, bolts=8, plateau_s=1650.0,
)
