"""OFFICES A, B and C: furnished office floors of rooms joined by doors.

One generator, three configurations. A building is a box of ``size`` with ``levels`` storeys.
Each storey is cut along y into bands (rows of rooms, or a corridor); a band is split along x into
equal rooms. Walls between bands carry a door in front of every room, walls between rooms of a
band carry a door at mid-depth, so every room has a door to a neighbour. Doors are 1.4 x 2.4 m,
wide enough for the 0.6 m vehicle. Storeys are joined by a stairwell: a hole in each upper slab
over a straight flight along one side, leaving a free shaft at least 1.4 m wide beside the stairs.

Furniture (desk clusters with chairs, monitors and lamps, partitions, book shelves along the
outer walls, plants, ceiling lights) is placed from the seeded generator, kept 1 m away from the
walls that carry doors and out of the stairwell.
"""

from __future__ import annotations

import dataclasses
import itertools
from dataclasses import dataclass

import numpy as np

from areas.area import Area, AreaInfo
from areas.assemble import finish_area
from areas.primitives import Parts, lathe, railing, slab, stairs, wall

GENERATOR_VERSION = 1

OUTER = 0.2  # exterior wall thickness
INNER = 0.12  # partition wall thickness
SLAB = 0.2
# Doors are 2.4 m high where the storey allows: a vehicle needs its 0.45 m safety radius above
# and below, and the clutter of a furnished room reaches 1.3 m.
DOOR_W, DOOR_H = 1.4, 2.4
# Start above the furniture (desk lamps reach 1.3 m) and below the ceiling lights.
START_Z = 1.95
STAIR_W = 1.0

Rect = tuple[float, float, float, float]


@dataclass(frozen=True)
class Band:
    """A row of rooms along x: ``depth`` metres along y split into ``rooms`` equal rooms."""

    depth: float
    rooms: int
    corridor: bool = False


@dataclass(frozen=True)
class OfficesConfig:
    """One office building.

    Attributes:
        size: (x, y, z) bounding volume in metres.
        levels: bands per storey, bottom storey first.
        stairwell: (x0, y0, x1, y1) plan rectangle of the slab holes, inside one room.
        desk_pitch: (x, y) spacing of desk clusters in metres; smaller means more furniture.
        segments: sides of round parts; the main knob of the face count.
        books: books per shelf board.
        lamp_chance: probability of a desk lamp on each desk.
    """

    name: str
    title: str
    size: tuple[float, float, float]
    levels: tuple[tuple[Band, ...], ...]
    stairwell: Rect | None
    start: tuple[float, float]
    desk_pitch: tuple[float, float]
    segments: int
    books: int
    lamp_chance: float
    plateau_s: float
    complexity: str


def _band_edges(bands: tuple[Band, ...], y_size: float) -> list[float]:
    edges = [0.0]
    for b in bands:
        edges.append(edges[-1] + b.depth)
    scale = y_size / edges[-1]
    return [e * scale for e in edges]


def _overlaps(rect: Rect, others: list[Rect]) -> bool:
    return any(rect[0] < o[2] and o[0] < rect[2] and rect[1] < o[3] and o[1] < rect[3]
               for o in others)


def _chair(p: Parts, x: float, y: float, z: float, yaw: float, seg: int) -> None:
    """An office chair: five-star base with castors, column, seat, back."""
    for k in range(5):
        a = yaw + 2.0 * np.pi * k / 5.0
        tip = (x + 0.28 * np.cos(a), y + 0.28 * np.sin(a), z + 0.07)
        p.cylinder((x, y, z + 0.08), tip, 0.02, max(6, seg // 4))
        p.cylinder((tip[0], tip[1], z + 0.001), (tip[0], tip[1], z + 0.05), 0.025, max(6, seg // 2))
    p.cylinder((x, y, z + 0.08), (x, y, z + 0.45), 0.03, seg)
    p.box((x - 0.23, y - 0.23, z + 0.45), (x + 0.23, y + 0.23, z + 0.52))
    bx, by = x - 0.25 * np.cos(yaw), y - 0.25 * np.sin(yaw)
    half = np.abs([0.22 * np.sin(yaw), 0.22 * np.cos(yaw)]) + 0.03
    p.box((bx - half[0], by - half[1], z + 0.55), (bx + half[0], by + half[1], z + 1.05))


def _desk(p: Parts, x: float, y: float, z: float, facing: float, rng: np.random.Generator,
          seg: int, lamp_chance: float) -> None:
    """A 1.6 x 0.8 m desk centred at (x, y) with chair, monitor, keyboard and sometimes a lamp;
    ``facing`` is +1 or -1: which side (along y) the user sits on."""
    p.box((x - 0.8, y - 0.4, z + 0.71), (x + 0.8, y + 0.4, z + 0.75))
    for sx in (-0.75, 0.75):
        for sy in (-0.35, 0.35):
            p.box((x + sx - 0.03, y + sy - 0.03, z), (x + sx + 0.03, y + sy + 0.03, z + 0.71))
    back = y - 0.25 * facing
    p.box((x - 0.28, back - 0.015, z + 0.9), (x + 0.28, back + 0.015, z + 1.22))
    p.cylinder((x, back, z + 0.75), (x, back, z + 0.9), 0.025, seg // 2)
    p.box((x - 0.22, y + 0.05 * facing - 0.07, z + 0.75),
          (x + 0.22, y + 0.05 * facing + 0.07, z + 0.77))
    if rng.random() < lamp_chance:
        lx = x + 0.6 * (1 if rng.random() < 0.5 else -1)
        p.add(lathe([[0.08, 0.0], [0.08, 0.02], [0.012, 0.03], [0.012, 0.4], [0.09, 0.45],
                     [0.05, 0.55]], (lx, back, z + 0.75), seg))
    _chair(p, x, y + 0.7 * facing, z, float(np.pi / 2.0 * facing + rng.normal(0.0, 0.3)), seg)


def _shelf(p: Parts, x0: float, x1: float, y_wall: float, inward: float, z: float,
           rng: np.random.Generator, books: int) -> None:
    """A 2 m book shelf from x0 to x1 against the wall at ``y_wall``, 0.35 m deep."""
    y0, y1 = sorted((y_wall, y_wall + 0.35 * inward))
    for xs in (x0, x1 - 0.03):
        p.box((xs, y0, z), (xs + 0.03, y1, z + 2.0))
    for k in range(5):
        zb = z + 0.05 + k * 0.45
        p.box((x0, y0, zb), (x1, y1, zb + 0.025))
        if k == 4 or books == 0:
            continue
        widths = rng.uniform(0.02, 0.06, books)
        xs_ = x0 + 0.04 + np.concatenate([[0.0], np.cumsum(widths + 0.004)[:-1]])
        fit = xs_ + widths < x1 - 0.04
        for bx, bw in zip(xs_[fit], widths[fit], strict=True):
            h = rng.uniform(0.2, 0.34)
            p.box((bx, y0 + 0.02, zb + 0.025), (bx + bw, y1 - 0.04, zb + 0.025 + h))


def _plant(p: Parts, x: float, y: float, z: float, seg: int) -> None:
    p.add(lathe([[0.16, 0.0], [0.2, 0.4], [0.05, 0.42], [0.03, 0.8], [0.3, 1.0], [0.25, 1.3],
                 [0.05, 1.45]], (x, y, z), seg))


def _room_furniture(p: Parts, cfg: OfficesConfig, room: Rect, z: float, keep_out: list[Rect],
                    shelf_walls: list[float], rng: np.random.Generator) -> None:
    """Furniture of one room (interior rectangle ``room``) whose floor is at height ``z``."""
    x0, y0, x1, y1 = room
    seg = cfg.segments
    px, py = cfg.desk_pitch
    margin = 1.0
    nx = max(0, int((x1 - x0 - 2 * margin + 0.4) // px))
    ny = max(0, int((y1 - y0 - 2 * margin + 0.4) // py))
    cx0 = (x0 + x1) / 2.0 - (nx - 1) * px / 2.0
    cy0 = (y0 + y1) / 2.0 - (ny - 1) * py / 2.0
    for i in range(nx):
        for j in range(ny):
            x, y = cx0 + i * px, cy0 + j * py
            # A cluster is two facing desks (1.6 x 1.6 m) with its chairs, 1.6 x 3.0 m in all.
            if _overlaps((x - 1.0, y - 1.6, x + 1.0, y + 1.6), keep_out) or rng.random() < 0.15:
                continue
            _desk(p, x, y - 0.4, z, -1.0, rng, seg, cfg.lamp_chance)
            _desk(p, x, y + 0.4, z, 1.0, rng, seg, cfg.lamp_chance)
            p.box((x - 0.8, y - 0.015, z + 0.75), (x + 0.8, y + 0.015, z + 1.2))
    for y_wall, inward in ((y0, 1.0), (y1, -1.0)):
        if y_wall not in shelf_walls:
            continue
        x = x0 + 0.3
        while x + 1.0 < x1 - 0.3:
            if not _overlaps((x, min(y_wall, y_wall + inward), x + 1.0,
                              max(y_wall, y_wall + inward)), keep_out) and rng.random() < 0.7:
                _shelf(p, x, x + 1.0, y_wall, inward, z, rng, cfg.books)
            x += 1.1
    for corner in ((x0 + 0.4, y0 + 0.4), (x1 - 0.4, y1 - 0.4)):
        if not _overlaps((corner[0] - 0.4, corner[1] - 0.4, corner[0] + 0.4, corner[1] + 0.4),
                         keep_out):
            _plant(p, corner[0], corner[1], z, seg)


def _door_spots(bands: tuple[Band, Band], x_size: float) -> list[float]:
    """Door positions along x in the wall between two bands: in front of each room of both
    bands (two in a room 10 m wide or more), at least 2 m apart."""
    doors: list[float] = []
    for bb in bands:
        if bb.corridor:
            continue
        bxs = np.linspace(0.0, x_size, bb.rooms + 1)
        for r0, r1 in itertools.pairwise(bxs):
            w = r1 - r0
            spots = [(r0 + r1) / 2.0] if w < 10 else [r0 + w / 4, r1 - w / 4]
            doors += [s for s in spots if all(abs(s - d) > 2.0 for d in doors)]
    return doors


def _band_walls(p: Parts, cfg: OfficesConfig, bands: tuple[Band, ...], floor: float, ceil: float,
                keep_out: list[Rect]) -> list[tuple[Rect, list[float]]]:
    """The inner walls of one storey, with their doors (kept free in ``keep_out``); returns
    each room's interior rectangle with the y of its walls that may carry shelves."""
    X, Y, _ = cfg.size
    edges = _band_edges(bands, Y)
    door_h = min(DOOR_H, ceil - floor - 0.3)
    room_rects: list[tuple[Rect, list[float]]] = []
    for b, band in enumerate(bands):
        ya, yb = edges[b], edges[b + 1]
        xs = np.linspace(0.0, X, band.rooms + 1)
        # Partition walls between the rooms of the band, each with a door at mid-depth.
        if not band.corridor:
            for xw in xs[1:-1]:
                yd = (ya + yb) / 2.0
                p.add(wall(1, ya, yb, float(xw), INNER, floor, ceil,
                           [(yd - DOOR_W / 2, floor, yd + DOOR_W / 2, floor + door_h)]))
                keep_out.append((xw - 1.0, yd - 1.0, xw + 1.0, yd + 1.0))
        # The wall to the next band: a door in front of each room of both bands.
        if b + 1 < len(bands):
            doors = _door_spots((band, bands[b + 1]), X)
            p.add(wall(0, 0.0, X, yb, INNER, floor, ceil,
                       [(d - DOOR_W / 2, floor, d + DOOR_W / 2, floor + door_h)
                        for d in doors]))
            keep_out += [(d - 1.0, yb - 1.0, d + 1.0, yb + 1.0) for d in doors]
        if band.corridor:
            continue
        for r0, r1 in itertools.pairwise(xs):
            inner = (max(r0, OUTER) + INNER / 2, max(ya, OUTER) + INNER / 2,
                     min(r1, X - OUTER) - INNER / 2, min(yb, Y - OUTER) - INNER / 2)
            # Shelves go only against exterior walls, which have no doors.
            outer_walls = [inner[1]] if ya < 1e-9 else []
            outer_walls += [inner[3]] if yb > Y - 1e-9 else []
            room_rects.append((inner, outer_walls))
    return room_rects


def _shell(p: Parts, cfg: OfficesConfig, storey: float, holes: list[Rect]) -> None:
    """Ground slab, roof slab, the slabs between storeys (holed by the stairwell) and the
    exterior walls over the full height."""
    X, Y, Z = cfg.size
    p.add(slab((0.0, 0.0, X, Y), 0.0, 0.15), slab((0.0, 0.0, X, Y), Z - 0.15, Z))
    for lvl in range(1, len(cfg.levels)):
        p.add(slab((0.0, 0.0, X, Y), lvl * storey - SLAB / 2, lvl * storey + SLAB / 2, holes))
    for axis, at in ((0, OUTER / 2), (0, Y - OUTER / 2), (1, OUTER / 2), (1, X - OUTER / 2)):
        p.add(wall(axis, 0.0, X if axis == 0 else Y, at, OUTER, 0.0, Z))


def _stair_flight(p: Parts, stairwell: Rect, floor: float, top: float) -> None:
    """The flight from ``floor`` up through the stairwell to ``top``, and a railing along the
    open side of the hole on the storey above."""
    sx0, sy0, sx1, sy1 = stairwell
    length = sy1 - sy0 - 0.2
    n_steps = max(2, round((top - floor) / 0.18))
    p.add(stairs((sx0 + 0.05 + STAIR_W / 2, sy0 + 0.1, floor), 1, 1.0, STAIR_W,
                 top - floor, run=length / n_steps))
    p.add(railing([(sx1 + 0.05, sy0, top), (sx1 + 0.05, sy1, top)]))


def _storey(p: Parts, cfg: OfficesConfig, lvl: int, storey: float, holes: list[Rect],
            rng: np.random.Generator) -> None:
    """Storey ``lvl``: its inner walls, furniture, ceiling lights and the flight up from it."""
    X, Y, Z = cfg.size
    n_levels = len(cfg.levels)
    floor = 0.15 if lvl == 0 else lvl * storey + SLAB / 2
    ceil = Z - 0.15 if lvl == n_levels - 1 else (lvl + 1) * storey - SLAB / 2
    keep_out: list[Rect] = []
    if cfg.stairwell:
        sx0, sy0, sx1, sy1 = cfg.stairwell
        keep_out.append((sx0 - 0.5, sy0 - 0.5, sx1 + 0.5, sy1 + 1.5))
    room_rects = _band_walls(p, cfg, cfg.levels[lvl], floor, ceil, keep_out)
    for inner, walls_ in room_rects:
        _room_furniture(p, cfg, inner, floor, keep_out, walls_, rng)
    # Ceiling lights on a 2.4 m grid.
    for lx in np.arange(1.6, X - 1.0, 2.4):
        for ly in np.arange(1.6, Y - 1.0, 2.4):
            if not _overlaps((lx - 0.6, ly - 0.15, lx + 0.6, ly + 0.15), holes):
                p.box((lx - 0.6, ly - 0.15, ceil - 0.06), (lx + 0.6, ly + 0.15, ceil))
    if cfg.stairwell and lvl + 1 < n_levels:
        _stair_flight(p, cfg.stairwell, floor, (lvl + 1) * storey + SLAB / 2)


MIN_ROOM_WIDTH = 3.5  # along x, when a seed other than 0 re-splits the bands


def varied_rooms(cfg: OfficesConfig, seed: int) -> OfficesConfig:
    """``cfg`` with its bands split into other numbers of rooms, chosen by ``seed`` (so its inner
    walls and doors move, not only its furniture); seed 0 keeps ``cfg``, the registered scene."""
    if seed == 0:
        return cfg
    rng = np.random.default_rng([seed, 1])  # apart from the furniture's draws
    most = max(1, int(cfg.size[0] // MIN_ROOM_WIDTH))
    levels = []
    for bands in cfg.levels:
        new = []
        for band in bands:
            rooms = band.rooms if band.corridor else int(rng.integers(1, most + 1))
            new.append(dataclasses.replace(band, rooms=rooms))
        levels.append(tuple(new))
    if all(a == b for a, b in zip(levels, cfg.levels, strict=True)):
        # Every band kept its rooms: re-split the first room band of the ground storey.
        b = next(i for i, band in enumerate(levels[0]) if not band.corridor)
        first = levels[0][b]
        rooms = first.rooms + 1 if first.rooms < most else first.rooms - 1
        if rooms >= 1 and rooms != first.rooms:
            levels[0] = (*levels[0][:b], dataclasses.replace(first, rooms=rooms),
                         *levels[0][b + 1:])
    return dataclasses.replace(cfg, levels=tuple(levels))


def build_offices(cfg: OfficesConfig, seed: int = 0) -> Area:
    """An office building per ``cfg``; the same seed gives identical arrays. Seeds other than 0
    also split the bands into other numbers of rooms (`varied_rooms`)."""
    rng = np.random.default_rng(seed)
    cfg = varied_rooms(cfg, seed)
    n_levels = len(cfg.levels)
    storey = cfg.size[2] / n_levels
    p = Parts()
    holes = [cfg.stairwell] if cfg.stairwell else []
    _shell(p, cfg, storey, holes)
    for lvl in range(n_levels):
        _storey(p, cfg, lvl, storey, holes, rng)
    start_x, start_y = cfg.start
    return finish_area(
        name=cfg.name, mesh=p.build(), bounds_min=np.zeros(3), bounds_max=np.array(cfg.size),
        start=(start_x, start_y, START_Z), yaw=0.0, plateau_s=cfg.plateau_s, voxel_size=0.1,
        info=AreaInfo(title=cfg.title, rooms=sum(b.rooms for lv in cfg.levels for b in lv),
                      levels=n_levels, complexity=cfg.complexity, indoor=True),
        generator_version=GENERATOR_VERSION, seed=seed,
    )


OFFICES_A = OfficesConfig(
    name="offices-a", title="OFFICES A", size=(22.0, 28.0, 3.4),
    levels=((Band(14.0, 1), Band(14.0, 1)),), stairwell=None, start=(11.0, 3.0),
    desk_pitch=(4.2, 4.8), segments=8, books=0, lamp_chance=0.0, plateau_s=600.0, complexity="low",
)
OFFICES_B = OfficesConfig(
    name="offices-b", title="OFFICES B", size=(8.0, 20.0, 12.0),
    levels=((Band(20.0, 1),),) * 4, stairwell=(0.25, 0.25, 2.75, 4.6), start=(4.0, 10.0),
    desk_pitch=(2.6, 3.4), segments=40, books=18, lamp_chance=0.5, plateau_s=750.0,
    complexity="intermediate",
)
OFFICES_C = OfficesConfig(
    name="offices-c", title="OFFICES C", size=(30.0, 16.0, 7.4),
    levels=((Band(6.8, 5), Band(2.4, 1, corridor=True), Band(6.8, 5)),
            (Band(6.8, 6), Band(2.4, 1, corridor=True), Band(6.8, 5))),
    stairwell=(0.25, 0.25, 2.75, 4.6), start=(15.0, 8.0),
    desk_pitch=(2.0, 3.4), segments=160, books=30, lamp_chance=1.0, plateau_s=1650.0,
    complexity="high",
)
