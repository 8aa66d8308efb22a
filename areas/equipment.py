"""Industrial parts shared by FACILITY, PLATFORM and POWERPLANT, built from the primitives.

Each function adds closed primitives to a `Parts` collector; ``seg`` is the number of sides of
round parts, the knob that sets an area's face count.
"""

from __future__ import annotations

import numpy as np

from areas.primitives import Parts, lathe, pipe_run


def tank(p: Parts, x: float, y: float, z: float, radius: float, height: float, seg: int) -> None:
    """A vertical tank on the floor at (x, y, z): cylindrical shell with a domed head, a nozzle
    and four legs."""
    leg = min(0.4, 0.15 * height)
    dome = [[radius * np.cos(a), height + 0.35 * radius * np.sin(a)]
            for a in np.linspace(0.0, np.pi / 2.0, 6)[:-1]]
    profile = [[radius * 0.98, leg], [radius, leg + 0.05], *dome, [0.25 * radius, height + 0.4 *
                                                                  radius]]
    p.add(lathe(profile, (x, y, z), seg))
    for k in range(4):
        a = np.pi / 4.0 + k * np.pi / 2.0
        lx, ly = x + 0.8 * radius * np.cos(a), y + 0.8 * radius * np.sin(a)
        p.box((lx - 0.05, ly - 0.05, z), (lx + 0.05, ly + 0.05, z + leg + 0.1))
    p.cylinder((x + radius * 0.9, y, z + 0.6 * height), (x + radius + 0.3, y, z + 0.6 * height),
               0.08, max(8, seg // 2))


def pump(p: Parts, x: float, y: float, z: float, axis: int, seg: int) -> None:
    """A pump skid: base plate, motor and volute, about 1.4 x 0.6 x 0.8 m, long side on ``axis``."""
    d = np.zeros(3)
    d[axis] = 1.0
    c = np.array([x, y, z])
    size = np.array([0.6, 0.6, 0.1])
    size[axis] = 1.4
    up = np.array([0.0, 0.0, 1.0])
    p.box_at(c + 0.05 * up, size)
    p.cylinder(c + 0.4 * up - 0.6 * d, c + 0.4 * up + 0.1 * d, 0.22, seg)
    p.cylinder(c + 0.4 * up + 0.15 * d, c + 0.4 * up + 0.5 * d, 0.3, seg)
    p.cylinder(c + 0.7 * up + 0.32 * d, c + 1.1 * up + 0.32 * d, 0.08, max(8, seg // 2))


def valve(p: Parts, at: np.ndarray, direction: np.ndarray, radius: float, seg: int) -> None:
    """A gate valve on a pipe at ``at`` (3,) along unit ``direction`` (3,): body, bonnet and
    handwheel above it."""
    p.cylinder(at - direction * radius * 1.5, at + direction * radius * 1.5, radius * 1.5, seg)
    top = at + np.array([0.0, 0.0, radius * 4.0 + 0.15])
    p.cylinder(at, top, radius * 0.4, max(8, seg // 2))
    p.cylinder(top, top + np.array([0.0, 0.0, 0.03]), radius * 2.0 + 0.05, seg)


def cabinet(p: Parts, lo: tuple[float, float, float], hi: tuple[float, float, float],
            facing: int, sign: float) -> None:
    """An electrical cabinet with a door handle on the side facing ``sign`` along ``facing``."""
    p.box(lo, hi)
    c = (np.array(lo) + np.array(hi)) / 2.0
    front = hi[facing] if sign > 0 else lo[facing]
    h0 = c.copy()
    h0[facing] = front
    h1 = h0.copy()
    h1[facing] = front + sign * 0.04
    p.cylinder(h0 - np.array([0.0, 0.0, 0.1]), h1 + np.array([0.0, 0.0, 0.1]), 0.012, 6)


def column(p: Parts, x: float, y: float, z0: float, z1: float, size: float = 0.3) -> None:
    """A structural I-column: two flanges and a web."""
    h = size / 2.0
    p.box((x - h, y - h, z0), (x + h, y - h + 0.02, z1))
    p.box((x - h, y + h - 0.02, z0), (x + h, y + h, z1))
    p.box((x - 0.01, y - h, z0), (x + 0.01, y + h, z1))


def pipe(p: Parts, points: list[tuple[float, float, float]], radius: float, seg: int,
         flange_every: float, bolts: int) -> None:
    """A flanged pipe along a polyline."""
    p.add(pipe_run(np.array(points, dtype=np.float64), radius, seg, flange_every, bolts))


def duct(p: Parts, x0: float, x1: float, y: float, z: float, w: float, h: float,
         axis: int = 0) -> None:
    """A rectangular duct along ``axis`` from ``x0`` to ``x1`` with a joint collar every 1.5 m."""
    lo = [0.0, 0.0, z - h / 2.0]
    hi = [0.0, 0.0, z + h / 2.0]
    lo[axis], hi[axis] = x0, x1
    lo[1 - axis], hi[1 - axis] = y - w / 2.0, y + w / 2.0
    p.box(lo, hi)
    for s in np.arange(x0 + 1.5, x1 - 0.1, 1.5):
        clo, chi = list(lo), list(hi)
        clo[axis], chi[axis] = s - 0.03, s + 0.03
        clo[1 - axis] -= 0.03
        chi[1 - axis] += 0.03
        clo[2] -= 0.03
        chi[2] += 0.03
        p.box(clo, chi)
