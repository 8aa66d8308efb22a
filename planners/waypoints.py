"""Turning voxel paths into waypoints, and finding where the vehicle stands on the grid."""

from __future__ import annotations

import numba
import numpy as np
import numpy.typing as npt

from planners.astar import PathCache
from planners.search import BoolGrid, IndexArray, segment_clear, shortcut
from sim.map_view import MapView
from sim.search_checks import segment_in_mask


def nearest_traversable(
    traversable: BoolGrid, voxel: IndexArray, reach: int = 3
) -> IndexArray | None:
    """`voxel` if traversable, else the nearest traversable voxel within `reach` voxels."""
    i, j, k = (int(v) for v in voxel)
    shape = traversable.shape
    if all(0 <= v < n for v, n in zip((i, j, k), shape, strict=True)) and traversable[i, j, k]:
        return np.array([i, j, k], dtype=np.int64)
    lo = np.maximum(np.array([i, j, k]) - reach, 0)
    hi = np.minimum(np.array([i, j, k]) + reach + 1, shape)
    if np.any(hi <= lo):
        return None
    sub = traversable[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]]
    cells = np.argwhere(sub)
    if len(cells) == 0:
        return None
    cells = cells + lo
    best = np.argmin(np.sum((cells - np.array([i, j, k])) ** 2, axis=1))
    return cells[best].astype(np.int64)


@numba.njit(cache=True)
def _escapes_clear(traversable: BoolGrid, free: BoolGrid, a: npt.NDArray[np.float64],
                   cells: IndexArray) -> npt.NDArray[np.bool_]:
    out = np.empty(cells.shape[0], dtype=np.bool_)
    for n in range(cells.shape[0]):
        out[n] = segment_in_mask(traversable, free, a, cells[n].astype(np.float64) + 0.5, True)
    return out


def escape_starts(view: MapView, position: npt.ArrayLike, reach: int) -> IndexArray:
    """(S, 3) the voxels a search may start from for the vehicle at `position` (world (3,)),
    nearest first: its own voxel alone when traversable; otherwise every traversable voxel
    within `reach` voxels on each axis that the straight leg from `position` enters through
    known free voxels only, as the framework lets a vehicle leave where the map no longer
    allows (`sim.search_checks.plan_is_clear`). Empty when there is none.

    `nearest_traversable` takes the nearest traversable voxel within three, whether the leg to
    it is flyable or not and whichever of several pockets it lies in; a caller that finds no
    way on from one start can try the next start of another pocket."""
    pos = np.asarray(position, dtype=np.float64)
    voxel = view.world_to_index(pos[None])[0]
    shape = np.array(view.shape)
    trav = view.traversable
    if np.all((voxel >= 0) & (voxel < shape)) and trav[voxel[0], voxel[1], voxel[2]]:
        return voxel[None].astype(np.int64)
    lo = np.maximum(voxel - reach, 0)
    hi = np.minimum(voxel + reach + 1, shape)
    if np.any(hi <= lo):
        return np.zeros((0, 3), dtype=np.int64)
    cells = np.argwhere(trav[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]]) + lo
    if len(cells) == 0:
        return np.zeros((0, 3), dtype=np.int64)
    a = (pos - view.origin) / view.voxel_size
    d2 = np.sum((cells + 0.5 - a) ** 2, axis=1)
    cells = cells[np.argsort(d2, kind="stable")].astype(np.int64)
    return cells[_escapes_clear(trav, view.free, a, np.ascontiguousarray(cells))]


def tree_root(view: MapView,
              position: npt.ArrayLike) -> tuple[npt.NDArray[np.float64] | None, bool]:
    """Where a tree of the vehicle's moves starts: its `position` (3,), or the nearest
    traversable voxel centre when it stands where the map no longer allows (True then); None
    when no traversable voxel is near."""
    here = np.asarray(position, dtype=np.float64)
    voxel = view.world_to_index(here[None])[0]
    start = nearest_traversable(view.traversable, voxel)
    if start is None:
        return None, False
    if np.array_equal(start, voxel):
        return here.copy(), False
    return view.index_to_world(start[None])[0], True


def grid_path(view: MapView, paths: PathCache, position: npt.ArrayLike,
              target: npt.ArrayLike) -> tuple[IndexArray, IndexArray] | None:
    """A shortest 26-connected path through traversable voxels, shortcut, from the vehicle at
    `position` to `target` (world (3,) each, snapped to the nearest traversable voxels), and its
    goal voxel; None when either has no traversable voxel near, both snap to one voxel, or no
    path joins them."""
    def snap(point: npt.ArrayLike) -> IndexArray | None:
        voxel = view.world_to_index(np.asarray(point, dtype=np.float64)[None])[0]
        return nearest_traversable(view.traversable, voxel)

    start, goal = snap(position), snap(target)
    if start is None or goal is None or np.array_equal(start, goal):
        return None
    path, _ = paths.path(view.traversable, start, goal, view.voxel_size)
    if len(path) < 2:
        return None
    return shortcut(path, view.traversable), goal


def shortcut_from_position(view: MapView, path: IndexArray,
                           position: npt.ArrayLike) -> IndexArray:
    """`shortcut(path)` for a voxel path (K, 3) that starts in the vehicle's own voxel, with its
    first leg flyable from the vehicle's exact `position` (world (3,)) rather than from that
    voxel's centre, where the search started.

    Where the straight leg from `position` to the shortcut path's second voxel leaves the
    traversable voxels, the second voxel is instead the farthest voxel of `path` that a straight
    leg from `position` reaches, and the rest is shortcut from there; `path_waypoints` then
    drops the own voxel. The shortcut path is returned unchanged when the path does not start in
    the own voxel or when its first leg is clear. A search that cuts no corners (`DistanceField`)
    leaves the next path voxel always reachable from within the own voxel; for a path whose
    steps may cut corners no leg may reach one, and the shortcut path is returned too
    (`path_waypoints` keeps the own voxel's centre as the first waypoint then)."""
    short = shortcut(path, view.traversable)
    if len(path) < 2:
        return short
    pos = np.asarray(position, dtype=np.float64)
    here = view.world_to_index(pos[None])[0]
    if not np.array_equal(path[0], here):
        return short
    start = (pos - view.origin) / view.voxel_size
    if segment_clear(view.traversable, start, short[1].astype(np.float64) + 0.5):
        return short
    centres = path.astype(np.float64) + 0.5
    far = len(path) - 1
    while far >= 1 and not segment_clear(view.traversable, start, centres[far]):
        far -= 1
    if far == 0:
        return short
    return np.vstack([path[:1], shortcut(path[far:], view.traversable)])


def path_waypoints(
    view: MapView,
    path: IndexArray,
    position: npt.NDArray[np.float64],
    look_at: npt.NDArray[np.float64],
) -> npt.NDArray[np.float64]:
    """(N, 4) waypoints along a voxel path from the vehicle's `position`.

    The first path voxel is dropped when it is the vehicle's own (a search may start from a
    nearby traversable voxel instead, which is then kept), unless the straight leg from the
    vehicle's exact position (not its voxel's centre, where the search started) to the next
    one leaves the traversable voxels. Each waypoint's yaw looks along the
    leg that ends there, so the camera sees where the vehicle flies; the last looks at `look_at`.
    """
    here = view.world_to_index(np.asarray(position)[None])[0]
    own = len(path) > 0 and bool(np.all(path[0] == here))
    if own and len(path) > 1:
        start = (np.asarray(position, dtype=np.float64) - view.origin) / view.voxel_size
        direct = segment_clear(view.traversable, start, path[1].astype(np.float64) + 0.5)
        keep = path[1:] if direct else path
    else:
        keep = path
    points = view.index_to_world(keep)
    waypoints = np.zeros((len(points), 4))
    waypoints[:, :3] = points
    previous = np.vstack([position[None], points[:-1]])
    legs = points - previous
    waypoints[:, 3] = np.arctan2(legs[:, 1], legs[:, 0])
    # A vertical or empty leg has no heading: keep the previous one.
    short = np.linalg.norm(legs[:, :2], axis=1) < 1e-6
    for n in np.flatnonzero(short):
        waypoints[n, 3] = waypoints[n - 1, 3] if n > 0 else waypoints[n, 3]
    final = look_at - points[-1]
    waypoints[-1, 3] = float(np.arctan2(final[1], final[0]))
    return waypoints
