"""The tree walks of `planners.segment_tree`, compiled with numba: branch sums and values, and
the nodes below a set of nodes."""

from __future__ import annotations

import numba
import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
IdArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]


@numba.njit(cache=True)
def branch_sums(parents: IdArray, gains: FloatArray,
                costs: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Branch sums and values of a tree given by `parents` ((N,), -1 for the root).

    Returns (N,) gain sums and cost sums from the root (its own excluded) and (N,) values
    (max of sum-gain / sum-cost over each node's subtree; 0 where the cost is 0).
    """
    n = parents.shape[0]
    depth = np.full(n, -1, dtype=np.int64)
    stack = np.empty(n, dtype=np.int64)
    for s in range(n):
        top = 0
        m = s
        while m >= 0 and depth[m] < 0:
            stack[top] = m
            top += 1
            m = parents[m]
        d = depth[m] if m >= 0 else -1
        while top > 0:
            top -= 1
            d += 1
            depth[stack[top]] = d
    order = np.argsort(depth, kind="mergesort")
    g = np.zeros(n)
    c = np.zeros(n)
    for o in range(n):
        m = order[o]
        p = parents[m]
        if p >= 0:
            g[m] = g[p] + gains[m]
            c[m] = c[p] + costs[m]
    value = np.zeros(n)
    for m in range(n):
        if c[m] > 0.0:
            value[m] = g[m] / c[m]
    for o in range(n - 1, -1, -1):
        m = order[o]
        p = parents[m]
        if p >= 0 and value[m] > value[p]:
            value[p] = value[m]
    return g, c, value


@numba.njit(cache=True)
def nodes_below(parents: IdArray, tops: BoolArray) -> BoolArray:
    """(N,) True on the `tops` nodes and on every node whose way up meets one of them."""
    n = parents.shape[0]
    state = np.zeros(n, dtype=np.int8)  # 0: not known yet, 1: below a top, 2: not
    for m in range(n):
        if tops[m]:
            state[m] = 1
    stack = np.empty(n, dtype=np.int64)
    for s in range(n):
        top = 0
        m = s
        while m >= 0 and state[m] == 0:
            stack[top] = m
            top += 1
            m = parents[m]
        found = state[m] if m >= 0 else 2
        while top > 0:
            top -= 1
            state[stack[top]] = found
    return state == 1
