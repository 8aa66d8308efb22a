"""ESM's failing samples, skipped in compiled code (`skip_failing_tries`).

Nearly every sample ESM draws fails to give a node: on OFFICES C about 99 of 100 (80,818 samples
for 809 nodes in 600 s of ESM-IPP v4), each failing after up to `steer_candidates` crops and
density tests in Python. `skip_failing_tries` draws a batch of the tries `Esm._expand` would make,
decides in one compiled call which of them `Esm._steer` surely returns None for, and leaves the
generator just past those: the first try that may succeed is then made exactly as before, so the
tree grows to the same bits.

"Surely" means that no rounding can change the decision. The screen computes what `_steer`
computes, in another order (its sums need not round as NumPy's or BLAS's do), and gives up,
leaving the try to `_steer`, wherever its result lies within a margin of a threshold: a distance
near `min_segment_m`, `crop_min_m` or `density_radius_m`, a point near a voxel
face, a near tie between the last of the nearest nodes and the next, a segment whose quarter-voxel
sample count rounding could change.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
import numpy.typing as npt

from planners.screen_margin import near_integer, near_value
from sim.map_view import MapView

FloatArray = npt.NDArray[np.float64]
BoolGrid = npt.NDArray[np.bool_]

# Tries drawn ahead per screening call: about 99 in 100 fail, so one batch usually ends at the
# next try worth making.
_BATCH = 64


@dataclass(frozen=True)
class SteerRule:
    """What `Esm._steer` and `Esm._crop` test, in metres (`planners.esm_config`)."""

    candidates: int
    extension_m: float
    crop_margin_m: float
    crop_min_m: float
    min_segment_m: float  # 0: no minimum (v1)
    density_radius_m: float


@numba.njit(cache=True)
def _walk(traversable: BoolGrid, a: FloatArray, b: FloatArray, steps: int) -> float:
    """`planners.lines._farthest_clear` (not escaping) over `steps` samples of a→b (voxel
    units): the last fraction whose samples up to it are all traversable, -1 when the start is
    not; NaN when a sample it reads lies within the margin of a voxel face."""
    nx, ny, nz = traversable.shape
    best = -1.0
    for s in range(steps + 1):
        t = s / steps
        x = a[0] + (b[0] - a[0]) * t
        y = a[1] + (b[1] - a[1]) * t
        z = a[2] + (b[2] - a[2]) * t
        if near_integer(x) or near_integer(y) or near_integer(z):
            return math.nan
        i, j, k = math.floor(x), math.floor(y), math.floor(z)
        if not (0 <= i < nx and 0 <= j < ny and 0 <= k < nz) or not traversable[i, j, k]:
            break
        best = t
    return best


@numba.njit(cache=True)
def _crop_fails_surely(positions: FloatArray, start: FloatArray, goal: FloatArray, full: float,
                       steps: int, crop_margin: float, crop_min: float, min_segment: float,
                       density: float, traversable: BoolGrid, origin: FloatArray,
                       voxel_size: float) -> bool:
    """Whether `_crop` from `start` toward `goal` (`full` metres away) surely gives None or a
    point nearer than `density` to a node, with its line sampled `steps` times."""
    a = (start - origin) / voxel_size
    b = (goal - origin) / voxel_size
    t = _walk(traversable, a, b, steps)
    if math.isnan(t):
        return False
    if t < 0.0:
        return True  # not even the start is traversable
    length = full
    if t < 1.0:
        length = t * full - crop_margin
        limit = min(crop_min, full)
        if near_value(length, limit):
            return False
        if length < limit:
            return True
    point = start + (goal - start) * (length / full)
    v = (point - origin) / voxel_size
    if near_integer(v[0]) or near_integer(v[1]) or near_integer(v[2]):
        return False
    i, j, k = math.floor(v[0]), math.floor(v[1]), math.floor(v[2])
    nx, ny, nz = traversable.shape
    if not (0 <= i < nx and 0 <= j < ny and 0 <= k < nz) or not traversable[i, j, k]:
        return True
    if min_segment > 0.0:
        if near_value(length, min_segment):
            return False
        if length < min_segment:
            return True
    nearest = math.inf
    for r in range(positions.shape[0]):
        d0 = positions[r, 0] - point[0]
        d1 = positions[r, 1] - point[1]
        d2 = positions[r, 2] - point[2]
        nearest = min(nearest, (d0 * d0 + d1 * d1) + d2 * d2)
    nearest = math.sqrt(nearest)
    if near_value(nearest, density):
        return False
    return nearest < density


@numba.njit(cache=True)
def _candidate_fails_surely(positions: FloatArray, node: int, sample: FloatArray,
                            extension: float, crop_margin: float, crop_min: float,
                            min_segment: float, density: float, traversable: BoolGrid,
                            origin: FloatArray, voxel_size: float) -> bool:
    """Whether steering from `node` toward `sample` surely gives no node (`_crop`, then the
    density test)."""
    start = positions[node]
    d = sample - start
    dist = math.sqrt((d[0] * d[0] + d[1] * d[1]) + d[2] * d[2])
    if min_segment > 0.0:
        if near_value(dist, min_segment):
            return False
        if dist < min_segment:
            return True
    if dist < 1e-3:
        return False
    # `steer`'s point moves continuously with the distance, so a distance near the extension
    # needs no margin of its own: either branch gives the same point to the last bits.
    if dist <= extension:
        goal, full = sample, dist
    else:
        goal, full = start + d * (extension / dist), extension
    # `_farthest_clear` samples the line every quarter voxel: ceil(4 x its length in voxels)
    # steps. A segment of the full extension is a whole number of quarter voxels long, where
    # rounding decides between two counts: it fails surely when it does with either.
    a = (start - origin) / voxel_size
    b = (goal - origin) / voxel_size
    span = math.sqrt(((b[0] - a[0]) ** 2 + (b[1] - a[1]) ** 2) + (b[2] - a[2]) ** 2) * 4.0
    if near_integer(span):
        n = max(1, math.floor(span + 0.5))
        return (_crop_fails_surely(positions, start, goal, full, n, crop_margin, crop_min,
                                   min_segment, density, traversable, origin, voxel_size)
                and _crop_fails_surely(positions, start, goal, full, n + 1, crop_margin,
                                       crop_min, min_segment, density, traversable, origin,
                                       voxel_size))
    return _crop_fails_surely(positions, start, goal, full, max(1, math.ceil(span)), crop_margin,
                              crop_min, min_segment, density, traversable, origin, voxel_size)


@numba.njit(cache=True)
def _sample_fails_surely(positions: FloatArray, sample: FloatArray, candidates: int,
                         extension: float, crop_margin: float, crop_min: float,
                         min_segment: float, density: float, traversable: BoolGrid,
                         origin: FloatArray, voxel_size: float) -> bool:
    """Whether `_steer` toward `sample` surely returns None: every one of the `candidates`
    nearest nodes fails. Their order does not matter then, only which nodes they are; a near
    tie between the last of them and the next could go either way."""
    n = positions.shape[0]
    count = min(candidates, n)
    # The count + 1 smallest squared distances, kept sorted by insertion.
    keep = count + 1 if count < n else count
    best_d = np.full(keep, math.inf)
    best_i = np.full(keep, -1, dtype=np.int64)
    for r in range(n):
        d0 = positions[r, 0] - sample[0]
        d1 = positions[r, 1] - sample[1]
        d2 = positions[r, 2] - sample[2]
        q = (d0 * d0 + d1 * d1) + d2 * d2
        if q >= best_d[keep - 1]:
            continue
        m = keep - 1
        while m > 0 and best_d[m - 1] > q:
            best_d[m] = best_d[m - 1]
            best_i[m] = best_i[m - 1]
            m -= 1
        best_d[m] = q
        best_i[m] = r
    if count < n and near_value(best_d[count], best_d[count - 1]):
        return False
    for c in range(count):
        if not _candidate_fails_surely(positions, best_i[c], sample, extension, crop_margin,
                                       crop_min, min_segment, density, traversable, origin,
                                       voxel_size):
            return False
    return True


@numba.njit(cache=True)
def _first_maybe(positions: FloatArray, samples: FloatArray, candidates: int, extension: float,
                 crop_margin: float, crop_min: float, min_segment: float, density: float,
                 traversable: BoolGrid, origin: FloatArray, voxel_size: float) -> int:
    """The first of `samples` toward which `_steer` may give a node; len(samples) if none."""
    for s in range(samples.shape[0]):
        if not _sample_fails_surely(positions, samples[s], candidates, extension, crop_margin,
                                    crop_min, min_segment, density, traversable, origin,
                                    voxel_size):
            return s
    return samples.shape[0]


def _draw(rng: np.random.Generator, local: int, total: int, centre: FloatArray,
          radius: float, lo: FloatArray, hi: FloatArray) -> FloatArray:
    """(total, 3) samples: `local` on the sphere of `radius` round `centre`, then the rest
    uniform in the box [lo, hi], drawing from `rng` as `Esm._expand` draws them one at a time
    (the screen only reads them: a sample it passes on is drawn again by `_expand`)."""
    directions = rng.normal(size=(local, 3))
    directions /= np.maximum(np.linalg.norm(directions, axis=1), 1e-12)[:, None]
    box = rng.uniform(lo, hi, size=(total - local, 3))
    samples: FloatArray = np.concatenate([centre + radius * directions, box])
    return samples


def skip_failing_tries(rng: np.random.Generator, positions: FloatArray, view: MapView,
                       rule: SteerRule, centre: FloatArray, radius: float, local_missing: int,
                       lo: FloatArray, hi: FloatArray, limit: int) -> int:
    """How many of the next tries (at most `limit`) `Esm._steer` surely gives no node for:
    the first `local_missing` sampled on the sphere of `radius` round `centre`, the others in
    the box [lo, hi]. Leaves `rng` just past them, where drawing them one at a time leaves it.

    `positions` ((N, 3), world metres) are the tree's nodes, which do not change while tries
    fail."""
    positions = np.ascontiguousarray(positions, dtype=np.float64)
    skipped = 0
    while skipped < limit:
        count = min(_BATCH, limit - skipped)
        local = min(count, max(local_missing - skipped, 0))
        state = rng.bit_generator.state
        samples = _draw(rng, local, count, centre, radius, lo, hi)
        first = _first_maybe(positions, samples, rule.candidates, rule.extension_m,
                             rule.crop_margin_m, rule.crop_min_m, rule.min_segment_m,
                             rule.density_radius_m, view.traversable, view.origin,
                             view.voxel_size)
        if first < count:
            # Back to the batch's start, then past the failing tries only.
            rng.bit_generator.state = state
            _draw(rng, min(first, local), first, centre, radius, lo, hi)
            return skipped + first
        skipped += count
    return skipped
