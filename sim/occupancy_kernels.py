"""The occupancy map's numba kernels: 3D-DDA traversal of depth rays and the log-odds update
(see `sim.occupancy` for the model and `sim.voxel_grid` for the grid convention)."""

from __future__ import annotations

import math

import numba
import numpy as np
import numpy.typing as npt

from sim.geometry import FloatArray
from sim.voxel_grid import (
    _FREE,
    _OCCUPIED,
    _UNKNOWN,
    BoolArray,
    IndexArray,
    LogOddsGrid,
    StateGrid,
)


@numba.njit(cache=True)
def _floor_in(x: float, n: int) -> int:
    """floor(x) clamped to [0, n - 1]."""
    return min(max(math.floor(x), 0), n - 1)


@numba.njit(cache=True)
def _axis_start(a: float, d: float, i: int) -> tuple[int, float, float]:
    """Step sign, t of the first face crossing out of voxel i, t between crossings."""
    if d > 0.0:
        return 1, (i + 1 - a) / d, 1.0 / d
    if d < 0.0:
        return -1, (i - a) / d, -1.0 / d
    return 0, math.inf, math.inf


@numba.njit(cache=True)
def _traverse(
    ax: float, ay: float, az: float, bx: float, by: float, bz: float,
    nx: int, ny: int, nz: int, buf: IndexArray, skip: npt.NDArray[np.uint8] | None,
) -> tuple[int, int, bool, int, int, int, int, int, int]:
    """3D-DDA (Amanatides & Woo) of the segment a→b clipped to the grid box.

    a, b: segment ends in grid units, (world - grid origin) / voxel_size; voxel (i, j, k) spans
        [i, i+1) x [j, j+1) x [k, k+1) and the box is [0, nx) x [0, ny) x [0, nz).
    buf: (M,) int64 with M >= nx + ny + nz; receives the flat C-order indices of the in-grid
        voxels the segment visits, in order, but those whose bit is set in `skip`
        (ceil(nx*ny*nz / 8),) (byte v >> 3, bit v & 7), when given. When b lies in the grid the
        last voxel visited is floor(b).

    Returns:
        count written, count visited, whether the last voxel visited is b's voxel, then the
        i, j, k of the first and of the last voxel visited (meaningless when none is).
    """
    dx = bx - ax
    dy = by - ay
    dz = bz - az
    ex = math.floor(bx)
    ey = math.floor(by)
    ez = math.floor(bz)
    end_in = 0 <= ex < nx and 0 <= ey < ny and 0 <= ez < nz
    end_flat = (ex * ny + ey) * nz + ez
    # Slab clipping to the grid box; t runs from 0 at a to 1 at b.
    t0 = 0.0
    t1 = 1.0
    if dx != 0.0:
        ta = -ax / dx
        tb = (nx - ax) / dx
        t0 = max(t0, min(ta, tb))
        t1 = min(t1, max(ta, tb))
    elif ax < 0.0 or ax >= nx:
        return 0, 0, False, 0, 0, 0, 0, 0, 0
    if dy != 0.0:
        ta = -ay / dy
        tb = (ny - ay) / dy
        t0 = max(t0, min(ta, tb))
        t1 = min(t1, max(ta, tb))
    elif ay < 0.0 or ay >= ny:
        return 0, 0, False, 0, 0, 0, 0, 0, 0
    if dz != 0.0:
        ta = -az / dz
        tb = (nz - az) / dz
        t0 = max(t0, min(ta, tb))
        t1 = min(t1, max(ta, tb))
    elif az < 0.0 or az >= nz:
        return 0, 0, False, 0, 0, 0, 0, 0, 0
    if not t0 < t1:
        # At most a single point of the segment touches the box.
        if end_in:
            buf[0] = end_flat
            return _kept(skip, end_flat), 1, True, ex, ey, ez, ex, ey, ez
        return 0, 0, False, 0, 0, 0, 0, 0, 0

    # First and last voxels; clamping absorbs rounding of points computed on the box faces.
    ix = _floor_in(ax + t0 * dx, nx)
    iy = _floor_in(ay + t0 * dy, ny)
    iz = _floor_in(az + t0 * dz, nz)
    if end_in:
        lx, ly, lz = ex, ey, ez
    else:
        lx = _floor_in(ax + t1 * dx, nx)
        ly = _floor_in(ay + t1 * dy, ny)
        lz = _floor_in(az + t1 * dz, nz)
    sx, tmx, tdx = _axis_start(ax, dx, ix)
    sy, tmy, tdy = _axis_start(ay, dy, iy)
    sz, tmz, tdz = _axis_start(az, dz, iz)
    # Face crossings left per axis. Counting them, rather than testing t against t1, keeps the
    # walk inside the grid and makes it end on the last voxel whatever the rounding.
    cx = (lx - ix) * sx
    cy = (ly - iy) * sy
    cz = (lz - iz) * sz
    if cx < 0 or cy < 0 or cz < 0:
        # Only when rounding puts the entry past the end (segment shorter than rounding).
        if end_in:
            buf[0] = end_flat
            return _kept(skip, end_flat), 1, True, ex, ey, ez, ex, ey, ez
        return 0, 0, False, 0, 0, 0, 0, 0, 0
    if cx == 0:
        tmx = math.inf
    if cy == 0:
        tmy = math.inf
    if cz == 0:
        tmz = math.inf
    stx = sx * ny * nz
    sty = sy * nz
    idx = (ix * ny + iy) * nz + iz
    n = cx + cy + cz
    # Each voxel is written to the next slot, which moves on unless the voxel is skipped.
    buf[0] = idx
    kept = _kept(skip, idx)
    for _ in range(n):
        if tmx <= tmy and tmx <= tmz:
            idx += stx
            cx -= 1
            tmx = math.inf if cx == 0 else tmx + tdx
        elif tmy <= tmz:
            idx += sty
            cy -= 1
            tmy = math.inf if cy == 0 else tmy + tdy
        else:
            idx += sz
            cz -= 1
            tmz = math.inf if cz == 0 else tmz + tdz
        buf[kept] = idx
        kept += _kept(skip, idx)
    return kept, n + 1, end_in, ix, iy, iz, lx, ly, lz


@numba.njit(cache=True, inline="always")
def _kept(skip: npt.NDArray[np.uint8] | None, v: int) -> int:
    """1 unless voxel v's bit is set in `skip` (never without one)."""
    if skip is None:
        return 1
    return 1 - ((skip[v >> 3] >> (v & 7)) & 1)


@numba.njit(cache=True, inline="always")
def _grow_box(box: IndexArray, i: int, j: int, k: int) -> None:
    """Grow the inclusive (6,) min i, j, k / max i, j, k box over voxel (i, j, k)."""
    box[0] = min(box[0], i)
    box[1] = min(box[1], j)
    box[2] = min(box[2], k)
    box[3] = max(box[3], i)
    box[4] = max(box[4], j)
    box[5] = max(box[5], k)


@numba.njit(cache=True, inline="always")
def _unflatten(v: int, ny: int, nz: int) -> tuple[int, int, int]:
    """(i, j, k) of the flat C-order index v in a (nx, ny, nz) grid."""
    q = v // nz
    i = q // ny
    return i, q - i * ny, v - q * nz


# Per voxel the kernel keeps two uint32 (`integrate_rays`' `voxels`, (nx*ny*nz, 2), one cache
# line): the tag of the last batch that touched the voxel, and its returns: bits 0-23 the mean
# of the points where rays returned in it, 8 bits per axis in 1/256ths of the voxel edge (value q
# stands for (q + 0.5) / 256), bits 24-28 how many returns that mean holds (so that a voxel holds
# at least n returns exactly when the word is at least n << 24, below `SETTLED`).
FRESH_TAG = (1 << 32) - 1  # a voxel never touched; tags stay below it
# The returns word of a voxel that misses drove to the log-odds floor: FREE, no returns, and no
# miss can change it, so the hot loop skips it after one read.
SETTLED = 1 << 31
_COUNT_SHIFT = 24
_COUNT_MASK = 31
_POS_STEPS = 256.0
# A voxel's diagonal in voxels: how far behind a lone return a surface may lie whose range noise
# it is.
_DIAGONAL = math.sqrt(3.0)
# 1 / n for the running mean over n returns.
_INVERSE = np.array([0.0] + [1.0 / n for n in range(1, _COUNT_MASK + 1)])


@numba.njit(cache=True, inline="always")
def _quantise(f: float) -> int:
    """A position in [0, 1) of a voxel's edge to 0..255."""
    return min(max(int(f * _POS_STEPS), 0), 255)


@numba.njit(cache=True)
def integrate_rays(
    origin: FloatArray, endpoints: FloatArray, hit: BoolArray,
    grid_origin: FloatArray, voxel_size: float,
    log_odds: LogOddsGrid, state: StateGrid,
    l_hit: float, l_miss: float, l_min: float, l_max: float, threshold: float,
    miss_radius: float, noise_sigmas: float, noise_a: float, noise_b: float, noise_z0: float,
    min_returns: int, window: int,
    touched: IndexArray, changed: IndexArray,
    voxels: npt.NDArray[np.uint32], settled: npt.NDArray[np.uint8], batch: int,
) -> int:
    """Update the grid with a batch of rays sharing one origin (one depth frame).

    Each voxel is updated at most once per batch, and hits win (as OctoMap does): a voxel in
    which any ray ends on a surface gets `l_hit`, and at least `threshold + l_hit`. Every other
    in-grid voxel that some ray passes through, or ends in without a return, gets `l_miss` -
    unless the voxel holds returns: from at least `min_returns` batches, only a ray that passes
    within `miss_radius` of their mean and, if it has a return, runs on past that point by more
    than `miss_radius` plus `noise_sigmas` standard deviations of the range noise at its length
    counts as a miss; from fewer batches, a ray that passes within `miss_radius` of their mean
    or returns near it along the ray (ends less than a voxel's diagonal plus that margin past
    the ray's nearest point to the mean). Rays passing elsewhere through the
    voxel leave it alone (the model and its reasons are `sim.occupancy`'s). A miss that brings a
    voxel to `l_min` forgets its returns. Each batch adds one return to the mean of each voxel
    rays returned in (that of the first such ray).
    Log-odds are clamped to [l_min, l_max]. Rays with a non-finite endpoint are skipped; parts of
    rays outside the grid are skipped; the origin may lie outside.

    `voxels` (nx*ny*nz, 2) uint32 holds, per voxel, the tag of the last batch that touched it
    and its returns (layout above; `FRESH_TAG` and 0 for a voxel never touched). `batch` must
    grow from call to call and stay below 2^30 (tags 4*batch: hit pending, 4*batch+1: miss
    applied, 4*batch+2: hit applied, 4*batch+3: hit applied and return recorded).
    `settled` (ceil(nx*ny*nz / 8),) uint8 holds one bit per voxel (byte v >> 3, bit v & 7 of
    flat index v), set exactly where the returns word is `SETTLED` (all clear for a new map).

    Args:
        origin: (3,) float64 sensor position, world metres.
        endpoints: (N, 3) float64 ray ends, world metres.
        hit: (N,) bool, True where the ray ends on a surface.
        grid_origin: (3,) float64 lower corner of voxel (0, 0, 0).
        log_odds: (nx, ny, nz) float32 C-contiguous, updated in place.
        state: (nx, ny, nz) uint8 C-contiguous `VoxelState`, updated in place.
        miss_radius: voxels.
        noise_a, noise_b, noise_z0: range noise sigma(L) = a + b (L - z0)^2, metres.
        min_returns: at most 31.
        window: the mean is a running mean of the first `window` returns, then moves by
            1/window of each new return's offset (at most 31).
        touched: (6,) int64 min i, j, k then max i, j, k of all voxels the rays visited, grown
            in place.
        changed: (6,) int64 the same for voxels whose state changed, grown in place.

    Returns:
        Number of voxels that went from UNKNOWN to known.
    """
    nx, ny, nz = log_odds.shape
    flat_l = log_odds.reshape(-1)
    flat_s = state.reshape(-1)
    words = voxels.reshape(-1)
    buf = np.empty(nx + ny + nz + 3, dtype=np.int64)
    ax = (origin[0] - grid_origin[0]) / voxel_size
    ay = (origin[1] - grid_origin[1]) / voxel_size
    az = (origin[2] - grid_origin[2]) / voxel_size
    if not (math.isfinite(ax) and math.isfinite(ay) and math.isfinite(az)):
        return 0
    radius_sq = miss_radius * miss_radius
    floor_l = np.float32(l_min)
    lifted = np.float32(min(threshold + l_hit, l_max))
    protected = min_returns << _COUNT_SHIFT
    lone = 1 << _COUNT_SHIFT
    newly = 0
    hit_tag = 4 * batch
    miss_tag = 4 * batch + 1
    done_tag = 4 * batch + 2
    recorded_tag = 4 * batch + 3
    # First pass: the voxels where rays end on a surface, so that the second pass skips them.
    for r in range(endpoints.shape[0]):
        if not hit[r]:
            continue
        bx = (endpoints[r, 0] - grid_origin[0]) / voxel_size
        by = (endpoints[r, 1] - grid_origin[1]) / voxel_size
        bz = (endpoints[r, 2] - grid_origin[2]) / voxel_size
        if not (math.isfinite(bx) and math.isfinite(by) and math.isfinite(bz)):
            continue
        # The walk of a ray ending in the grid ends in floor(b) (see `_traverse`).
        ex = math.floor(bx)
        ey = math.floor(by)
        ez = math.floor(bz)
        if 0 <= ex < nx and 0 <= ey < ny and 0 <= ez < nz:
            v = (ex * ny + ey) * nz + ez
            words[2 * v] = hit_tag
            # A hit voxel leaves SETTLED in this batch (its return is recorded below): its bit
            # is cleared now, so that the second pass does not step over it.
            settled[v >> 3] &= np.uint8(255 ^ (1 << (v & 7)))
    for r in range(endpoints.shape[0]):
        bx = (endpoints[r, 0] - grid_origin[0]) / voxel_size
        by = (endpoints[r, 1] - grid_origin[1]) / voxel_size
        bz = (endpoints[r, 2] - grid_origin[2]) / voxel_size
        if not (math.isfinite(bx) and math.isfinite(by) and math.isfinite(bz)):
            continue
        # Most voxels a ray crosses are free space settled at the floor, where no miss acts
        # and (their bits cleared above) no hit falls: the walk leaves them out of `buf`.
        count, visited, end_in, fi, fj, fk, li, lj, lk = _traverse(
            ax, ay, az, bx, by, bz, nx, ny, nz, buf, settled)
        if visited == 0:
            continue
        dx = bx - ax
        dy = by - ay
        dz = bz - az
        # How far past a voxel's returns this ray must run to contradict them, in voxels;
        # worked out when the ray first meets such a voxel (-1 until then).
        margin = -1.0
        length = 0.0
        first_change = -1
        last_change = -1
        # Inline rather than a per-voxel function call: this loop is the hot path.
        for c in range(count):
            v = buf[c]
            tag = np.int64(words[2 * v])
            returns = np.int64(0)
            if tag == hit_tag:
                delta = l_hit
                words[2 * v] = done_tag
            elif hit_tag < tag <= recorded_tag:
                continue  # updated in this batch already
            else:
                # Never `SETTLED` here: the walk left those voxels out of `buf` (a settled hit
                # voxel, its bit cleared, takes the branch above).
                returns = np.int64(words[2 * v + 1])
                if returns >= lone:
                    if margin < 0.0:
                        length = math.sqrt(dx * dx + dy * dy + dz * dz)
                        margin = 0.0
                        if hit[r]:
                            range_m = length * voxel_size - noise_z0
                            sigma_m = noise_a + noise_b * range_m * range_m
                            margin = miss_radius + noise_sigmas * sigma_m / voxel_size
                    i, j, k = _unflatten(v, ny, nz)
                    wx = i + ((returns & 255) + 0.5) / _POS_STEPS - ax
                    wy = j + (((returns >> 8) & 255) + 0.5) / _POS_STEPS - ay
                    wz = k + (((returns >> 16) & 255) + 0.5) / _POS_STEPS - az
                    # t: where along the ray (0 at the origin, 1 at its end) it passes nearest.
                    t = (wx * dx + wy * dy + wz * dz) / (length * length) if length > 0.0 \
                        else 0.0
                    # How far the ray runs on past that point, in voxels.
                    beyond = (1.0 - t) * length
                    if returns >= protected:
                        # A surface seen here: only a ray through where it was seen contradicts
                        # it.
                        if hit[r] and beyond <= margin:
                            continue  # the ray returned there, within the noise
                        lateral = True
                    else:
                        # A lone return: a surface found just behind it may be what it is the
                        # range noise of, and a ray through it contradicts it; a ray passing
                        # beside it and running on says nothing of it.
                        lateral = not (hit[r] and beyond <= margin + _DIAGONAL)
                    if lateral:
                        t = min(max(t, 0.0), 1.0)
                        wx -= t * dx
                        wy -= t * dy
                        wz -= t * dz
                        if wx * wx + wy * wy + wz * wz > radius_sq:
                            continue  # it passed beside what was seen
                delta = l_miss
                words[2 * v] = miss_tag
            new = np.float32(min(max(flat_l[v] + delta, l_min), l_max))
            if delta > 0.0:
                # A return is believed until a ray contradicts it: the voxel is occupied, at
                # least as firmly as after a lone hit.
                new = max(new, lifted)
            flat_l[v] = new
            if delta < 0.0 and new <= floor_l:
                # A miss drove the voxel to the floor: it forgets its returns.
                words[2 * v + 1] = SETTLED
                settled[v >> 3] |= np.uint8(1 << (v & 7))
            # The state follows the stored float32, so state == (log_odds > threshold).
            s_new = _OCCUPIED if new > threshold else _FREE
            s_old = flat_s[v]
            if s_new != s_old:
                flat_s[v] = s_new
                if s_old == _UNKNOWN:
                    newly += 1
                if first_change < 0:
                    first_change = c
                last_change = c
        if hit[r] and end_in:
            v = buf[count - 1]  # the end voxel: a hit voxel, never skipped, and the last
            if words[2 * v] == done_tag:
                # The first ray of the batch to return in this voxel: add its return to the
                # running mean of where in the voxel rays return.
                words[2 * v] = recorded_tag
                returns = np.int64(words[2 * v + 1])
                n = min(int((returns >> _COUNT_SHIFT) & _COUNT_MASK) + 1, window)
                ex = math.floor(bx)
                ey = math.floor(by)
                ez = math.floor(bz)
                qx = _quantise(bx - ex)
                qy = _quantise(by - ey)
                qz = _quantise(bz - ez)
                if n > 1:
                    w = _INVERSE[n]
                    px = int(returns & 255)
                    py = int((returns >> 8) & 255)
                    pz = int((returns >> 16) & 255)
                    qx = px + math.floor((qx - px) * w + 0.5)
                    qy = py + math.floor((qy - py) * w + 0.5)
                    qz = pz + math.floor((qz - pz) * w + 0.5)
                words[2 * v + 1] = (n << _COUNT_SHIFT) | (qz << 16) | (qy << 8) | qx
        # A DDA path is monotone on every axis, so the first and last of any of its voxels
        # bound all of them.
        _grow_box(touched, fi, fj, fk)
        _grow_box(touched, li, lj, lk)
        if first_change >= 0:
            i, j, k = _unflatten(buf[first_change], ny, nz)
            _grow_box(changed, i, j, k)
            i, j, k = _unflatten(buf[last_change], ny, nz)
            _grow_box(changed, i, j, k)
    return newly


def decode_returns(returns: npt.NDArray[np.uint32]) -> tuple[FloatArray, npt.NDArray[np.int64]]:
    """(K, 3) mean return positions inside their voxels, in voxel edges (0..1), and (K,) how
    many returns they hold, from the voxels' return words (K,)."""
    w = np.asarray(returns, dtype=np.int64)
    count = (w >> _COUNT_SHIFT) & _COUNT_MASK
    q = np.stack([(w >> (8 * a)) & 255 for a in range(3)], axis=-1)
    return (q + 0.5) / _POS_STEPS, count


@numba.njit(cache=True)
def _ray_voxels(a: FloatArray, b: FloatArray, nx: int, ny: int, nz: int) -> IndexArray:
    """(K, 3) int64 voxels segment a→b (grid units) visits in the grid, in order."""
    buf = np.empty(nx + ny + nz + 3, dtype=np.int64)
    count = _traverse(a[0], a[1], a[2], b[0], b[1], b[2], nx, ny, nz, buf, None)[0]
    out = np.empty((count, 3), dtype=np.int64)
    for c in range(count):
        out[c, 0], out[c, 1], out[c, 2] = _unflatten(buf[c], ny, nz)
    return out
