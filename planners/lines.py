"""Collision-free straight-line checks in world coordinates, shared by every planner.

All checks sample a segment every quarter voxel, as the framework's own check
(`sim.search_checks.segment_in_mask`) does, so a segment a planner finds clear is one the
framework accepts.
"""

from __future__ import annotations

import numba
import numpy as np
import numpy.typing as npt

from planners.search import BoolGrid
from sim.map_view import MapView
from sim.search_checks import segment_in_mask

FloatArray = npt.NDArray[np.float64]


def to_voxel_units(view: MapView, points: npt.ArrayLike) -> FloatArray:
    """(..., 3) world points to continuous voxel coordinates (voxel (i, j, k) spans [i, i+1))."""
    return (np.asarray(points, dtype=np.float64) - view.origin) / view.voxel_size


@numba.njit(cache=True)
def _segments_clear(mask: BoolGrid, a: FloatArray, b: FloatArray) -> npt.NDArray[np.bool_]:
    out = np.empty(a.shape[0], dtype=np.bool_)
    for n in range(a.shape[0]):
        out[n] = segment_in_mask(mask, mask, a[n], b[n], False)
    return out


def segments_clear(view: MapView, mask: BoolGrid, a: npt.ArrayLike,
                   b: npt.ArrayLike) -> npt.NDArray[np.bool_]:
    """(N,) whether each world segment a[n]→b[n] ((N, 3) each) stays in `mask` voxels."""
    av = np.atleast_2d(to_voxel_units(view, a))
    bv = np.atleast_2d(to_voxel_units(view, b))
    return _segments_clear(mask, np.ascontiguousarray(av), np.ascontiguousarray(bv))


def segment_clear_world(view: MapView, mask: BoolGrid, a: npt.ArrayLike,
                        b: npt.ArrayLike) -> bool:
    """Whether the world segment a→b ((3,) each) stays in `mask` voxels."""
    return bool(segments_clear(view, mask, np.asarray(a)[None], np.asarray(b)[None])[0])


@numba.njit(cache=True)
def _farthest_clear(traversable: BoolGrid, free: BoolGrid, a: FloatArray, b: FloatArray,
                    escaping: bool) -> float:
    """Largest fraction t of a→b (voxel units) whose quarter-voxel samples up to t all pass
    the framework's test: traversable, or, while `escaping`, known free before the first
    traversable sample (a vehicle standing where the map no longer allows may leave through
    known free space); -1 when not even the start passes."""
    nx, ny, nz = traversable.shape
    length = np.sqrt(np.sum((b - a) ** 2))
    steps = max(1, int(np.ceil(length * 4.0)))
    best = -1.0
    for s in range(steps + 1):
        t = s / steps
        i = int(np.floor(a[0] + (b[0] - a[0]) * t))
        j = int(np.floor(a[1] + (b[1] - a[1]) * t))
        k = int(np.floor(a[2] + (b[2] - a[2]) * t))
        if i < 0 or j < 0 or k < 0 or i >= nx or j >= ny or k >= nz:
            break
        if traversable[i, j, k]:
            escaping = False
            best = t
        elif not (escaping and free[i, j, k]):
            break
    return best


@numba.njit(cache=True)
def _farthest_clear_many(traversable: BoolGrid, free: BoolGrid, a: FloatArray,
                         b: FloatArray, escaping: bool) -> FloatArray:
    out = np.empty(b.shape[0])
    for n in range(b.shape[0]):
        out[n] = _farthest_clear(traversable, free, a, b[n], escaping)
    return out


def _escape_grid(view: MapView, escaping: bool) -> BoolGrid:
    """The known-free grid the line tests read while escaping. When not escaping they never
    read it, so the traversable grid stands in: making the free grid is a pass over the whole
    map, several times a line test's cost."""
    return view.free if escaping else view.traversable


def reachable_lengths(view: MapView, a: npt.ArrayLike, b: npt.ArrayLike, *,
                      escaping: bool = False) -> FloatArray:
    """(N,) how far (metres) the vehicle can fly in a straight line from `a` ((3,) world)
    toward each of `b` ((N, 3) world), by the test of `farthest_clear_point` (before its
    final confirmation); -1 when not even the start qualifies."""
    av = to_voxel_units(view, a)
    bv = np.ascontiguousarray(np.atleast_2d(to_voxel_units(view, b)))
    t = _farthest_clear_many(view.traversable, _escape_grid(view, escaping), av, bv, escaping)
    lengths = t * np.linalg.norm(np.atleast_2d(b) - np.asarray(a, dtype=np.float64), axis=1)
    result: FloatArray = np.where(t < 0.0, -1.0, lengths)
    return result


def farthest_clear_point(view: MapView, a: npt.ArrayLike, b: npt.ArrayLike, *,
                         escaping: bool = False) -> FloatArray | None:
    """The point of the world segment a→b farthest from a that the vehicle can fly to in a
    straight line from a (see `_farthest_clear`); None when not even the start qualifies.

    `escaping` lets a start outside traversable space leave through known free voxels, as the
    framework allows; off by default, since such a way out may run along a wall whose surface
    the sensor noise left free."""
    av, bv = to_voxel_units(view, a), to_voxel_units(view, b)
    free = _escape_grid(view, escaping)
    t = _farthest_clear(view.traversable, free, av, bv, escaping)
    if t < 0.0:
        return None
    # The samples of the shorter segment a→(a + t (b - a)) are not those of a→b: confirm it
    # with the framework's own test, backing off a quarter voxel at a time.
    back = 0.25 / max(float(np.linalg.norm(bv - av)), 1e-9)
    while t > 0.0 and not segment_in_mask(view.traversable, free, av,
                                          av + t * (bv - av), escaping):
        t -= back
    if t <= 0.0:
        t = 0.0
    pa, pb = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    result: FloatArray = pa + t * (pb - pa)
    return result
