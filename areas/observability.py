"""What the benchmark vehicle can reach and what its camera can see from there.

One definition of "reachable", shared with the planners' rules (`sim.clearance`): a voxel centre
is **traversable** when every point of every blocked voxel's cube, and everything outside the
grid, lies at least the safety radius (vehicle radius plus margin, 0.45 m) away. The vehicle can
be anywhere in the traversable voxels 6-connected to the start (the *reachable* set); it cannot
pass an opening narrower than about twice the safety radius.

A free voxel is **observable** when it is reachable, or when a straight line from some reachable
voxel centre to its centre is at most the camera's range long, crosses no blocked voxel and
rises or falls no more than the camera's vertical half field of view (the camera is level and
turns with the vehicle's yaw, so any azimuth is seen). The seen set grows outward from the
reachable voxels (`_grow_seen`); each free voxel it borders is tested by rays cast from it:
first toward its nearest reachable voxel (its elevation clamped to the band), then along a fixed
set of directions spread evenly over the camera's elevation band; it is observable when a ray
meets a reachable voxel before a blocked one, within range. A voxel seen only through a gap
narrower than the directions' spacing can be missed: the observable set errs on the side of
what can surely be seen, so 100 % coverage stays possible.

The surface a camera sees is then the surface layer touching the observable free voxels
(`areas.ground_truth`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
import numpy.typing as npt
from scipy import ndimage

BoolArray = npt.NDArray[np.bool_]
IntArray = npt.NDArray[np.int64]

# Distances from a voxel centre to another voxel's cube are half-integers per axis (in voxels);
# the tolerance keeps a centre exactly at the radius traversable despite the radius's rounding
# (the same rule and tolerance as `sim.clearance`).
_TOLERANCE = 1e-6


@dataclass(frozen=True)
class ViewModel:
    """The vehicle and camera the observable set is computed for.

    The defaults are the benchmark's (`sim.config.EpisodeConfig`: vehicle radius 0.3 m plus a
    0.15 m margin; `sim.camera.CameraConfig`: 5 m range, 73.7 degree vertical field of view);
    `tests/areas/test_observability.py` holds them equal.

    Attributes:
        safety_radius_m: clearance from a traversable centre to every blocked cube, metres.
        range_m: camera range, metres.
        vertical_half_fov_deg: half the camera's vertical field of view, degrees.
        directions: rays cast from each voxel that is not reachable.
    """

    safety_radius_m: float = 0.45
    range_m: float = 5.0
    vertical_half_fov_deg: float = 36.85
    directions: int = 384


@dataclass(frozen=True)
class Observability:
    """The reachable and observable free space of an area (module docstring).

    Attributes:
        free_component: (nx, ny, nz) bool, free voxels 6-connected to the start voxel.
        reachable: (nx, ny, nz) bool, traversable voxels 6-connected to the start's.
        observable_free: (nx, ny, nz) bool, free voxels a camera on the vehicle can see,
            the reachable ones included.
    """

    free_component: BoolArray
    reachable: BoolArray
    observable_free: BoolArray


def traversable(blocked: BoolArray, voxel_size: float, radius_m: float) -> BoolArray:
    """(nx, ny, nz) bool: free voxels whose centre is at least ``radius_m`` from every point of
    every blocked voxel's cube and of everything outside the grid.

    The squared distance from a centre to a cube d voxels away is the sum over axes of
    (max(|d| - 1/2, 0) * voxel_size)^2, so its minimum over the blocked voxels is separable: three
    windowed minimum passes, one per axis, over the grid padded with blocked voxels.
    """
    margin = math.ceil(radius_m / voxel_size + 0.5)
    # Per-axis terms in quarter voxels squared: (2|d| - 1)^2 = 4 (|d| - 1/2)^2, 0 for d = 0.
    terms = [0 if d == 0 else (2 * abs(d) - 1) ** 2 for d in range(-margin, margin + 1)]
    far = np.int32(3 * (2 * margin + 1) ** 2)
    best = np.where(np.pad(blocked, margin, constant_values=True), np.int32(0), far)
    for axis in range(3):
        best = _window_min(best, terms, margin, axis)
    inner = best[margin:-margin, margin:-margin, margin:-margin]
    need = 4.0 * (radius_m / voxel_size) ** 2 - _TOLERANCE
    result: BoolArray = (inner >= need) & ~blocked
    return result


def _window_min(values: npt.NDArray[np.int32], terms: list[int], margin: int,
                axis: int) -> npt.NDArray[np.int32]:
    """min over d in [-margin, margin] of values shifted by d along ``axis`` plus terms[d]; the
    padding's blocked border keeps every shift inside the array."""
    out = values.copy()
    n = values.shape[axis]
    for offset, term in zip(range(-margin, margin + 1), terms, strict=True):
        if offset == 0:
            continue
        lo, hi = max(0, -offset), min(n, n - offset)
        dst = [slice(None)] * 3
        src = [slice(None)] * 3
        dst[axis] = slice(lo, hi)
        src[axis] = slice(lo + offset, hi + offset)
        np.minimum(out[tuple(dst)], values[tuple(src)] + np.int32(term), out=out[tuple(dst)])
    return out


def band_directions(count: int, half_fov_deg: float) -> npt.NDArray[np.float64]:
    """(count, 3) unit vectors spread evenly over the band of elevations within ``half_fov_deg``
    of the horizontal (a Fibonacci lattice on that zone of the sphere)."""
    top = math.sin(math.radians(half_fov_deg))
    i = np.arange(count, dtype=np.float64) + 0.5
    z = top * (2.0 * i / count - 1.0)
    azimuth = i * math.pi * (3.0 - math.sqrt(5.0))
    ring = np.sqrt(1.0 - z * z)
    return np.stack([ring * np.cos(azimuth), ring * np.sin(azimuth), z], axis=1)


def observability(blocked: BoolArray, start: tuple[int, int, int], voxel_size: float,
                  view: ViewModel | None = None) -> Observability:
    """The free component of ``start``, the vehicle's reachable set and the observable free
    voxels (module docstring). ``start`` is a free voxel's index; when its centre is not
    traversable, the reachable set grows from the traversable voxel nearest to it."""
    view = view or ViewModel()
    six = ndimage.generate_binary_structure(3, 1)
    labels, _ = ndimage.label(~blocked, structure=six)
    free_component = labels == labels[start]
    del labels
    walkable = traversable(blocked, voxel_size, view.safety_radius_m)
    reachable = _component_at(walkable, start, six)
    observable = reachable.copy()
    if reachable.any():
        # Distance (voxels) from every voxel to its nearest reachable one, and which one it is.
        distance, nearest = ndimage.distance_transform_edt(~reachable, return_indices=True)
        reach = view.range_m / voxel_size
        # A line of sight through free voxels is a 6-connected path: only the start's free
        # component can be seen.
        candidate = free_component & ~reachable & (distance <= reach)
        del distance
        twenty_six = ndimage.generate_binary_structure(3, 3)
        seeds = np.flatnonzero(candidate & ndimage.binary_dilation(reachable, twenty_six))
        seen = _grow_seen(seeds.astype(np.int64), candidate, reachable, blocked,
                          nearest.astype(np.int32),
                          band_directions(view.directions, view.vertical_half_fov_deg),
                          reach, math.tan(math.radians(view.vertical_half_fov_deg)))
        observable |= seen
    return Observability(free_component, reachable, observable)


def _component_at(mask: BoolArray, start: tuple[int, int, int],
                  structure: npt.NDArray[np.bool_]) -> BoolArray:
    """The 6-connected component of ``mask`` holding ``start``, or the one holding the voxel of
    ``mask`` nearest to it; all False when ``mask`` is empty."""
    if not mask.any():
        return np.zeros_like(mask)
    labels, _ = ndimage.label(mask, structure=structure)
    label = labels[start]
    if label == 0:
        _, nearest = ndimage.distance_transform_edt(~mask, return_indices=True)
        label = labels[tuple(int(nearest[axis][start]) for axis in range(3))]
    component: BoolArray = labels == label
    return component


@numba.njit(cache=True)
def _ray_meets(origin: npt.NDArray[np.float64], direction: npt.NDArray[np.float64],
               length: float, reachable: BoolArray, blocked: BoolArray) -> bool:
    """Whether a ray from ``origin`` (voxel units, grid frame) meets a reachable voxel before a
    blocked one or the grid's edge, within ``length`` voxels (3D-DDA, Amanatides and Woo)."""
    nx, ny, nz = reachable.shape
    cell = np.empty(3, dtype=np.int64)
    step = np.empty(3, dtype=np.int64)
    t_max = np.empty(3)
    t_delta = np.empty(3)
    for a in range(3):
        cell[a] = math.floor(origin[a])
        if direction[a] > 0.0:
            step[a] = 1
            t_max[a] = (cell[a] + 1.0 - origin[a]) / direction[a]
            t_delta[a] = 1.0 / direction[a]
        elif direction[a] < 0.0:
            step[a] = -1
            t_max[a] = (origin[a] - cell[a]) / -direction[a]
            t_delta[a] = -1.0 / direction[a]
        else:
            step[a] = 0
            t_max[a] = np.inf
            t_delta[a] = np.inf
    while True:
        a = 0
        if t_max[1] < t_max[a]:
            a = 1
        if t_max[2] < t_max[a]:
            a = 2
        if t_max[a] > length:
            return False
        cell[a] += step[a]
        t_max[a] += t_delta[a]
        i, j, k = cell[0], cell[1], cell[2]
        if i < 0 or j < 0 or k < 0 or i >= nx or j >= ny or k >= nz or blocked[i, j, k]:
            return False
        if reachable[i, j, k]:
            return True


@numba.njit(cache=True)
def _seen(i: int, j: int, k: int, target: npt.NDArray[np.int32], reachable: BoolArray,
          blocked: BoolArray, directions: npt.NDArray[np.float64], reach: float,
          max_slope: float) -> bool:
    """Whether a ray from voxel (i, j, k)'s centre connects it to a reachable voxel
    (`_ray_meets`).

    The rays tried, in order: toward ``target``, its nearest reachable voxel, the elevation
    clamped to the camera's band; eight azimuths at the band's edge on that voxel's side (up or
    down); then every one of ``directions``. The first two find most voxels in a ray or two;
    only voxels that are not seen pay for the whole set.
    """
    origin = np.array([i + 0.5, j + 0.5, k + 0.5])
    ray = np.empty(3)
    dx = float(target[0] - i)
    dy = float(target[1] - j)
    dz = float(target[2] - k)
    horizontal = math.sqrt(dx * dx + dy * dy)
    up = 1.0 if dz >= 0.0 else -1.0
    if horizontal > 0.0:
        dz = min(abs(dz), max_slope * horizontal) * up
        norm = math.sqrt(horizontal * horizontal + dz * dz)
        ray[0], ray[1], ray[2] = dx / norm, dy / norm, dz / norm
        if _ray_meets(origin, ray, reach, reachable, blocked):
            return True
    rise = max_slope / math.sqrt(1.0 + max_slope * max_slope)
    run = 1.0 / math.sqrt(1.0 + max_slope * max_slope)
    for q in range(8):
        angle = q * math.pi / 4.0
        ray[0], ray[1], ray[2] = run * math.cos(angle), run * math.sin(angle), rise * up
        if _ray_meets(origin, ray, reach, reachable, blocked):
            return True
    for r in range(len(directions)):
        if _ray_meets(origin, directions[r], reach, reachable, blocked):
            return True
    return False


@numba.njit(cache=True)
def _grow_seen(seeds: IntArray, candidate: BoolArray, reachable: BoolArray, blocked: BoolArray,
               nearest: npt.NDArray[np.int32], directions: npt.NDArray[np.float64],
               reach: float, max_slope: float) -> BoolArray:
    """(nx, ny, nz) bool: the candidate voxels seen from the reachable ones (`_seen`).

    The seen set grows outward from the reachable voxels: a candidate is tested only once one
    of its 26 neighbours is reachable or seen. The voxel next to a seen voxel on its line of
    sight is itself seen, so the growth reaches every seen voxel, and of the voxels that are not
    seen only the layer bordering the seen ones is tested: the space behind walls costs nothing.

    seeds: flat indices of the candidates touching a reachable voxel; nearest: (3, nx, ny, nz)
    index of each voxel's nearest reachable voxel.
    """
    nx, ny, nz = candidate.shape
    tested = np.zeros(candidate.shape, dtype=np.bool_)
    seen = np.zeros(candidate.shape, dtype=np.bool_)
    queue = np.empty(candidate.size, dtype=np.int64)
    target = np.empty(3, dtype=np.int32)
    head, tail = 0, 0
    for s in seeds:
        i, j, k = s // (ny * nz), (s // nz) % ny, s % nz
        if not tested[i, j, k]:
            tested[i, j, k] = True
            queue[tail] = s
            tail += 1
    while head < tail:
        s = queue[head]
        head += 1
        i, j, k = s // (ny * nz), (s // nz) % ny, s % nz
        for a in range(3):
            target[a] = nearest[a, i, j, k]
        if not _seen(i, j, k, target, reachable, blocked, directions, reach, max_slope):
            continue
        seen[i, j, k] = True
        for di in range(-1, 2):
            for dj in range(-1, 2):
                for dk in range(-1, 2):
                    a, b, c = i + di, j + dj, k + dk
                    if a < 0 or b < 0 or c < 0 or a >= nx or b >= ny or c >= nz:
                        continue
                    if candidate[a, b, c] and not tested[a, b, c]:
                        tested[a, b, c] = True
                        queue[tail] = (a * ny + b) * nz + c
                        tail += 1
    return seen
