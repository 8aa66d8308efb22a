"""FALCON's local ordering: a sequential ordering problem (SOP) over the frontiers near the
vehicle and the rest of the coverage path, the zones keeping their coverage-path order.

Nodes: the vehicle (the start), the coverage path's zones c_1..c_m, which must be visited in
that order, and k frontier viewpoints, which may be visited anywhere between them. The path is
open (it ends wherever its last node is). FALCON solves this with a branch-and-bound SOP solver
(its `sop_solver`, one second at most); here it is solved exactly by dynamic programming over
(frontiers visited, zones passed, current node), O(2^k m k^2), for k up to `MAX_FRONTIERS`.
"""

from __future__ import annotations

import numba
import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

MAX_FRONTIERS = 12


@numba.njit(cache=True)
def _solve(start_f: FloatArray, start_z1: float, ff: FloatArray, fz: FloatArray,
           zf: FloatArray, zz: FloatArray) -> IntArray:
    k = ff.shape[0]
    m = fz.shape[1]
    full = (1 << k) - 1
    # best[mask, j, l]: least cost having visited the frontiers in `mask` and zones 1..j, now at
    # frontier l (l < k) or at zone j (l == k; zone 0 is the start).
    best = np.full((1 << k, m + 1, k + 1), np.inf)
    came = np.full((1 << k, m + 1, k + 1), -1, dtype=np.int64)
    best[0, 0, k] = 0.0
    for mask in range(full + 1):
        for j in range(m + 1):
            for lo in range(k + 1):
                here = best[mask, j, lo]
                if here == np.inf:
                    continue
                state = (mask * (m + 1) + j) * (k + 1) + lo
                for f in range(k):
                    if (mask >> f) & 1:
                        continue
                    if lo < k:
                        c = ff[lo, f]
                    elif j == 0:
                        c = start_f[f]
                    else:
                        c = zf[j - 1, f]
                    nxt = mask | (1 << f)
                    if here + c < best[nxt, j, f]:
                        best[nxt, j, f] = here + c
                        came[nxt, j, f] = state
                if j < m:
                    if lo < k:
                        c = fz[lo, j]
                    elif j == 0:
                        c = start_z1
                    else:
                        c = zz[j - 1]
                    if here + c < best[mask, j + 1, k]:
                        best[mask, j + 1, k] = here + c
                        came[mask, j + 1, k] = state
    # Every node visited: all frontiers and all zones.
    end_l = 0
    end_cost = np.inf
    for lo in range(k + 1):
        if best[full, m, lo] < end_cost:
            end_cost = best[full, m, lo]
            end_l = lo
    out = np.zeros(k + m, dtype=np.int64)
    state = (full * (m + 1) + m) * (k + 1) + end_l
    pos = k + m - 1
    while pos >= 0:
        lo = state % (k + 1)
        j = (state // (k + 1)) % (m + 1)
        out[pos] = lo if lo < k else k + j - 1
        mask = state // ((k + 1) * (m + 1))
        state = came[mask, j, lo]
        pos -= 1
    return out


def solve_sop(start: npt.ArrayLike, between: npt.ArrayLike, to_zone: npt.ArrayLike,
              from_zone: npt.ArrayLike, zone_steps: npt.ArrayLike) -> IntArray:
    """The visiting order of least total cost.

    Args:
        start: (k + 1,) cost from the vehicle to each frontier, then to the first zone.
        between: (k, k) cost between frontiers.
        to_zone: (k, m) cost from each frontier to each zone.
        from_zone: (m, k) cost from each zone to each frontier.
        zone_steps: (m - 1,) cost from zone j to zone j + 1 (the coverage path's legs).

    Returns:
        (k + m,) node order after the vehicle: frontier f is f, zone j is k + j; zones appear in
        increasing order.
    """
    s = np.asarray(start, dtype=np.float64)
    ff = np.ascontiguousarray(between, dtype=np.float64)
    k = ff.shape[0]
    if k > MAX_FRONTIERS:
        raise ValueError(f"at most {MAX_FRONTIERS} frontiers, got {k}")
    fz = np.ascontiguousarray(to_zone, dtype=np.float64)
    if fz.ndim != 2 or fz.shape[0] != k:
        raise ValueError(f"to_zone must be (k, m) with k = {k}, got {fz.shape}")
    m = fz.shape[1]
    zf = np.ascontiguousarray(from_zone, dtype=np.float64).reshape(m, k)
    steps = np.asarray(zone_steps, dtype=np.float64).reshape(-1)
    if s.shape != (k + 1,) or steps.shape != (max(m - 1, 0),):
        raise ValueError("start needs k + 1 costs and zone_steps m - 1")
    for name, a in (("start", s), ("between", ff), ("to_zone", fz), ("from_zone", zf),
                    ("zone_steps", steps)):
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name} must be finite")
    zz = np.concatenate([steps, [0.0]])  # padded so that zz[j - 1] exists for every j < m
    return _solve(s[:k].copy(), float(s[k]) if m else 0.0, ff, fz, zf, zz)
