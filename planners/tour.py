"""Asymmetric travelling salesman tours over a cost matrix.

FUEL (Zhou et al., RA-L 2021) orders its frontier clusters by an asymmetric TSP solved with
LKH. Here the tour is exact by Held-Karp dynamic programming up to `exact_max_nodes` nodes, and
beyond that a nearest-neighbour tour improved by 2-opt (segment reversal, costed in both
directions since the matrix is asymmetric) and Or-opt (moving runs of one to three nodes, either
way round) until neither improves it: a local optimum, not LKH's much deeper search.

A tour is a closed cycle through every node, returned as a node order starting at node 0. An
open path from node 0 (FUEL's use) is the cycle of a matrix whose column 0 is zero: returning
to the start costs nothing.
"""

from __future__ import annotations

import numba
import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


def tour_cost(cost: FloatArray, tour: npt.ArrayLike) -> float:
    """Length of the closed cycle `tour` (a node order) under `cost` (n, n)."""
    t = np.asarray(tour, dtype=np.int64)
    return float(np.sum(cost[t, np.roll(t, -1)]))


@numba.njit(cache=True)
def _held_karp(cost: FloatArray) -> IntArray:
    n = cost.shape[0]
    m = n - 1  # nodes 1..n-1 are bits 0..m-1
    full = (1 << m) - 1
    dp = np.full((1 << m, m), np.inf)
    parent = np.full((1 << m, m), -1, dtype=np.int64)
    for j in range(m):
        dp[1 << j, j] = cost[0, j + 1]
    for mask in range(1, full + 1):
        for j in range(m):
            if not (mask >> j) & 1:
                continue
            here = dp[mask, j]
            if here == np.inf:
                continue
            for k in range(m):
                if (mask >> k) & 1:
                    continue
                nxt = mask | (1 << k)
                c = here + cost[j + 1, k + 1]
                if c < dp[nxt, k]:
                    dp[nxt, k] = c
                    parent[nxt, k] = j
    best, last = np.inf, 0
    for j in range(m):
        c = dp[full, j] + cost[j + 1, 0]
        if c < best:
            best, last = c, j
    tour = np.zeros(n, dtype=np.int64)
    mask = full
    for pos in range(n - 1, 0, -1):
        tour[pos] = last + 1
        prev = parent[mask, last]
        mask &= ~(1 << last)
        last = prev
    return tour


@numba.njit(cache=True)
def _nearest_neighbour(cost: FloatArray) -> IntArray:
    n = cost.shape[0]
    tour = np.zeros(n, dtype=np.int64)
    used = np.zeros(n, dtype=np.bool_)
    used[0] = True
    for pos in range(1, n):
        cur = tour[pos - 1]
        best, pick = np.inf, -1
        for k in range(n):
            if not used[k] and (pick < 0 or cost[cur, k] < best):
                best, pick = cost[cur, k], k
        tour[pos] = pick
        used[pick] = True
    return tour


@numba.njit(cache=True)
def _two_opt_pass(cost: FloatArray, tour: IntArray) -> bool:
    """First improving segment reversal; True when one was applied."""
    n = tour.shape[0]
    # fwd[k] / rev[k]: cost of the first k legs of the tour walked forward / backward.
    fwd = np.zeros(n)
    rev = np.zeros(n)
    for k in range(1, n):
        fwd[k] = fwd[k - 1] + cost[tour[k - 1], tour[k]]
        rev[k] = rev[k - 1] + cost[tour[k], tour[k - 1]]
    for i in range(1, n - 1):
        a = tour[i - 1]
        for j in range(i + 1, n):
            b = tour[(j + 1) % n]
            old = cost[a, tour[i]] + (fwd[j] - fwd[i]) + cost[tour[j], b]
            new = cost[a, tour[j]] + (rev[j] - rev[i]) + cost[tour[i], b]
            if new < old - 1e-9:
                tour[i:j + 1] = tour[i:j + 1][::-1].copy()
                return True
    return False


@numba.njit(cache=True)
def _or_opt_pass(cost: FloatArray, tour: IntArray) -> bool:
    """First improving move of a run of 1-3 nodes elsewhere, kept or reversed."""
    n = tour.shape[0]
    for length in range(1, 4):
        for i in range(1, n - length + 1):
            s0, s1 = tour[i], tour[i + length - 1]
            prev, nxt = tour[i - 1], tour[(i + length) % n]
            inner_f = 0.0
            inner_r = 0.0
            for k in range(i, i + length - 1):
                inner_f += cost[tour[k], tour[k + 1]]
                inner_r += cost[tour[k + 1], tour[k]]
            removed = cost[prev, s0] + cost[s1, nxt] - cost[prev, nxt]
            for p in range(n):
                if i - 1 <= p <= i + length - 1:
                    continue
                a, b = tour[p], tour[(p + 1) % n]
                keep = cost[a, s0] + cost[s1, b] - cost[a, b]
                flip = cost[a, s1] + cost[s0, b] - cost[a, b] + inner_r - inner_f
                if min(keep, flip) < removed - 1e-9:
                    seg = tour[i:i + length].copy()
                    if flip < keep:
                        seg = seg[::-1].copy()
                    rest = np.concatenate((tour[:i], tour[i + length:]))
                    # p indexes the old tour; in `rest` the slot after old p is:
                    at = p + 1 if p < i else p + 1 - length
                    tour[:] = np.concatenate((rest[:at], seg, rest[at:]))
                    return True
    return False


@numba.njit(cache=True)
def _local_search(cost: FloatArray, tour: IntArray, max_moves: int) -> IntArray:
    moves = 0
    while moves < max_moves:
        if _two_opt_pass(cost, tour) or _or_opt_pass(cost, tour):
            moves += 1
            continue
        break
    # Rotate back so that node 0 leads (Or-opt may move runs across the end).
    start = 0
    for k in range(tour.shape[0]):
        if tour[k] == 0:
            start = k
    return np.concatenate((tour[start:], tour[:start]))


def solve_atsp(cost: npt.ArrayLike, exact_max_nodes: int = 12,
               max_moves: int = 10_000) -> IntArray:
    """A short closed cycle through every node of the (n, n) asymmetric `cost` matrix.

    Exact (Held-Karp, O(2^n n^2)) for n <= `exact_max_nodes`; otherwise nearest neighbour from
    node 0 improved by 2-opt and Or-opt, at most `max_moves` improving moves.

    Returns:
        (n,) int64 node order, starting at node 0.
    """
    c = np.ascontiguousarray(cost, dtype=np.float64)
    if c.ndim != 2 or c.shape[0] != c.shape[1]:
        raise ValueError(f"cost must be square, got {c.shape}")
    if not np.all(np.isfinite(c)):
        raise ValueError("cost must be finite")
    n = c.shape[0]
    if n <= 3:
        # One, two or three nodes: both orders of three differ, so compare them.
        if n == 3 and tour_cost(c, [0, 2, 1]) < tour_cost(c, [0, 1, 2]):
            return np.array([0, 2, 1], dtype=np.int64)
        return np.arange(n, dtype=np.int64)
    if n <= exact_max_nodes:
        return _held_karp(c)
    return _local_search(c, _nearest_neighbour(c), max_moves)
