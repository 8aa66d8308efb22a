"""PLATFORM A and B: outdoor multi-deck process platforms.

One generator, two configurations. On a ground slab covering the whole bounding footprint stands
a steel structure inset by ``margin`` from the footprint's edges: columns on a grid, beams under
each deck, grated decks with railings along their edges and a stair opening, straight stairs
between decks, tanks, horizontal vessels, pumps and pipe runs on every level, and risers between
decks. Tall items (vent stacks, a lattice derrick on PLATFORM B) reach the top of the bounding
volume. The vehicle reaches every deck by flying up in the margin around the structure and over
the railings (the gap between a railing top and the beams of the deck above is at least 1.2 m),
or through the stair openings.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from areas.area import Area, AreaInfo
from areas.assemble import finish_area
from areas.equipment import column, pipe, pump, tank, valve
from areas.primitives import Parts, beams, railing, slab, stairs

GENERATOR_VERSION = 1

DECK = 0.1
BEAM = 0.35
RAIL = 1.1


@dataclass(frozen=True)
class PlatformConfig:
    """One platform.

    Attributes:
        size: (x, y, z) bounding volume, metres.
        decks: heights of the decks above the ground, metres.
        margin: free band between the structure and the footprint edge, metres.
        grid: column spacing, metres.
        items: equipment items per level.
        derrick: whether a lattice derrick rises to the top of the volume.
        segments: sides of round parts.
        voxel_size: occupancy voxel edge, metres.
    """

    name: str
    title: str
    size: tuple[float, float, float]
    decks: tuple[float, ...]
    margin: float
    grid: float
    items: int
    derrick: bool
    segments: int
    flange_every: float
    bolts: int
    voxel_size: float
    plateau_s: float
    complexity: str


def _level_items(p: Parts, cfg: PlatformConfig, lo: tuple[float, float], hi: tuple[float, float],
                 z: float, head: float, keep_out: list[tuple[float, float, float, float]],
                 rng: np.random.Generator) -> None:
    """Equipment on one level (floor at ``z``, ``head`` metres free above) in the rectangle."""
    seg = cfg.segments
    placed = list(keep_out)
    for _ in range(cfg.items * 6):
        if len(placed) - len(keep_out) >= cfg.items:
            break
        kind = rng.choice(["tank", "vessel", "pump"], p=[0.4, 0.35, 0.25])
        half = {"tank": (1.2, 1.2), "vessel": (2.2, 1.0), "pump": (1.0, 0.6)}[str(kind)]
        x = rng.uniform(lo[0] + half[0] + 0.3, hi[0] - half[0] - 0.3)
        y = rng.uniform(lo[1] + half[1] + 0.3, hi[1] - half[1] - 0.3)
        # 1.3 m of clearance around every item keeps passages wide enough to fly through.
        rect = (x - half[0] - 1.3, y - half[1] - 1.3, x + half[0] + 1.3, y + half[1] + 1.3)
        if any(rect[0] < o[2] and o[0] < rect[2] and rect[1] < o[3] and o[1] < rect[3]
               for o in placed):
            continue
        placed.append((x - half[0], y - half[1], x + half[0], y + half[1]))
        if kind == "tank":
            tank(p, x, y, z, float(rng.uniform(0.7, 1.1)), float(min(head - 1.3, rng.uniform(
                1.5, 4.0))), seg)
        elif kind == "vessel":
            r = float(min(0.8, (head - 1.2) / 2.5))
            zc = z + 0.3 + r
            for sx in (-1.2, 1.2):
                p.box((x + sx - 0.1, y - 0.6 * r, z), (x + sx + 0.1, y + 0.6 * r, zc))
            p.cylinder((x - 2.0, y, zc), (x + 2.0, y, zc), r, seg)
            pipe(p, [(x + 1.5, y, zc + r), (x + 1.5, y, zc + r + 0.6), (x + 1.5, y + 1.6,
                                                                          zc + r + 0.6)],
                 0.06, max(8, seg // 2), cfg.flange_every, cfg.bolts)
        else:
            pump(p, x, y, z, 0, seg)
            valve(p, np.array([x + 0.32, y, z + 1.0]), np.array([0.0, 0.0, 1.0]), 0.06,
                  max(8, seg // 2))


def _derrick(p: Parts, x: float, y: float, z0: float, z1: float, base: float) -> None:
    """A tapered four-legged lattice tower from z0 to z1 with bracing every 2.5 m."""
    top = base * 0.3
    levels = np.arange(z0, z1 + 1e-9, 2.5)
    if levels[-1] < z1 - 1e-9:
        levels = np.append(levels, z1)

    def corner(k: int, z: float) -> tuple[float, float, float]:
        w = base + (top - base) * (z - z0) / (z1 - z0)
        sx, sy = (-1, -1, 1, 1)[k], (-1, 1, 1, -1)[k]
        return (x + sx * w / 2.0, y + sy * w / 2.0, z)

    for k in range(4):
        p.add(beams([corner(k, z0)], [corner(k, z1)], 0.2, 0.2))
        for za, zb in itertools.pairwise(levels):
            p.add(beams([corner(k, za)], [corner((k + 1) % 4, zb)], 0.08, 0.08))
            p.add(beams([corner(k, zb)], [corner((k + 1) % 4, zb)], 0.1, 0.1))


def build_platform(cfg: PlatformConfig, seed: int = 0) -> Area:
    """A platform per ``cfg``; the same seed gives identical arrays."""
    rng = np.random.default_rng(seed)
    X, Y, Z = cfg.size
    m = cfg.margin
    p = Parts()
    p.add(slab((0.0, 0.0, X, Y), 0.0, 0.15))
    x0, y0, x1, y1 = m, m, X - m, Y - m
    cols_x = np.linspace(x0 + 0.2, x1 - 0.2, max(2, round((x1 - x0) / cfg.grid) + 1))
    cols_y = np.linspace(y0 + 0.2, y1 - 0.2, max(2, round((y1 - y0) / cfg.grid) + 1))
    top_deck = cfg.decks[-1]
    for cx in cols_x:
        for cy in cols_y:
            column(p, float(cx), float(cy), 0.15, top_deck - DECK, 0.3)
    # Stair openings alternate between the two x ends so flights do not stack.
    floors = [0.15, *cfg.decks]
    for i, z in enumerate(cfg.decks):
        hx = x0 + 1.2 if i % 2 == 0 else x1 - 1.2 - 5.0
        hole = (hx, y0 + 0.8, hx + 5.0, y0 + 0.8 + 2.4)
        p.add(slab((x0, y0, x1, y1), z - DECK, z, [hole]))
        # Beams under the deck along x on every column line, along y at the ends.
        for cy in cols_y:
            p.add(beams([(x0, cy, z - DECK - BEAM / 2)], [(x1, cy, z - DECK - BEAM / 2)], 0.2,
                        BEAM))
        for cx in (cols_x[0], cols_x[-1]):
            p.add(beams([(cx, y0, z - DECK - BEAM / 2)], [(cx, y1, z - DECK - BEAM / 2)], 0.2,
                        BEAM))
        p.add(railing([(x0 + 0.05, y0 + 0.05, z), (x1 - 0.05, y0 + 0.05, z),
                       (x1 - 0.05, y1 - 0.05, z), (x0 + 0.05, y1 - 0.05, z),
                       (x0 + 0.05, y0 + 0.05, z)], RAIL))
        p.add(railing([(hole[0], hole[3] + 0.05, z), (hole[2], hole[3] + 0.05, z)], RAIL))
        below = floors[i]
        n = max(2, round((z - below) / 0.18))
        run = (hole[2] - hole[0] - 0.3) / n
        p.add(stairs((hole[0] + 0.1, hole[1] + 0.6, below), 0, 1.0, 1.0, z - below, run=run))

    for i, z in enumerate(floors):
        head = (cfg.decks[i] - DECK - BEAM if i < len(cfg.decks) else Z) - z
        hx = x0 + 1.2 if i % 2 == 0 else x1 - 6.2
        keep = [(hx - 0.5, y0, hx + 5.5, y0 + 4.0)]
        if i > 0:
            ph = x0 + 1.2 if (i - 1) % 2 == 0 else x1 - 6.2
            keep.append((ph - 0.5, y0, ph + 5.5, y0 + 4.0))
        if cfg.derrick and i == len(floors) - 1:
            keep.append(((X - 6.0) / 2, (Y - 6.0) / 2, (X + 6.0) / 2, (Y + 6.0) / 2))
        _level_items(p, cfg, (x0, y0), (x1, y1), z, min(head, 6.0), keep, rng)
        # Pipe runs along x under each deck (or above the top deck's railing), on hangers.
        if i < len(cfg.decks):
            zp = cfg.decks[i] - DECK - BEAM - 0.25
            for k, yk in enumerate(np.linspace(y1 - 3.0, y1 - 1.5, 4)):
                pipe(p, [(x0 + 0.3, float(yk), zp - 0.25 * (k % 2)),
                         (x1 - 0.3, float(yk), zp - 0.25 * (k % 2))],
                     float(rng.choice([0.05, 0.08, 0.1])), cfg.segments, cfg.flange_every,
                     cfg.bolts)
    # Risers through all decks at two corners.
    for rx, ry in ((x1 - 0.8, y1 - 0.8), (x0 + 0.8, y1 - 0.8)):
        pipe(p, [(rx, ry, 0.15), (rx, ry, top_deck + 1.5)], 0.12, cfg.segments,
             cfg.flange_every * 2, cfg.bolts)
    # Vent stacks reaching the top of the volume.
    for vx, vy in ((x0 + 1.0, y0 + 5.0), (x1 - 1.0, y0 + 5.0)):
        p.cylinder((vx, vy, top_deck), (vx, vy, Z), 0.2, cfg.segments)
    if cfg.derrick:
        _derrick(p, X / 2.0, Y / 2.0, top_deck, Z, 5.0)

    return finish_area(
        name=cfg.name, mesh=p.build(), bounds_min=np.zeros(3), bounds_max=np.array(cfg.size),
        start=(m / 2.0 + 0.1, Y / 2.0, 1.5), yaw=0.0, plateau_s=cfg.plateau_s,
        voxel_size=cfg.voxel_size,
        info=AreaInfo(title=cfg.title, rooms=None, levels=len(floors),
                      complexity=cfg.complexity, indoor=False),
        generator_version=GENERATOR_VERSION, seed=seed,
    )


PLATFORM_A = PlatformConfig(
    name="platform-a", title="PLATFORM A", size=(16.0, 24.0, 9.0), decks=(3.2, 6.4), margin=1.6,
    grid=4.5, items=3, derrick=False, segments=64, flange_every=0.5, bolts=10, voxel_size=0.1,
    plateau_s=550.0, complexity="intermediate",
)
PLATFORM_B = PlatformConfig(
    name="platform-b", title="PLATFORM B", size=(24.0, 20.0, 25.0), decks=(7.0, 14.0),
    margin=2.0, grid=5.0, items=5, derrick=True, segments=32, flange_every=0.6, bolts=8,
    voxel_size=0.2, plateau_s=1200.0, complexity="high",
)
