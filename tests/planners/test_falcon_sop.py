"""FALCON's solvers and costs against brute force: the sequential ordering problem, the layered
refinement, and the time lower bound."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from planners.falcon import _first_of_cheapest
from planners.falcon_costs import Dynamics, time_cost
from planners.falcon_sop import MAX_FRONTIERS, solve_sop

DYN = Dynamics(v_max=1.5, a_max=2.5, vz_max=1.0, yaw_rate=1.0, yaw_acc=2.0)


def _order_cost(order: list[int], k: int, start: np.ndarray, ff: np.ndarray, fz: np.ndarray,
                zf: np.ndarray, steps: np.ndarray) -> float:
    """Cost of visiting `order` (frontiers 0..k-1, zones k..) from the vehicle."""
    total, prev = 0.0, -1
    for node in order:
        if prev == -1:
            total += start[node] if node < k else start[k]
        elif prev < k and node < k:
            total += ff[prev, node]
        elif prev < k:
            total += fz[prev, node - k]
        elif node < k:
            total += zf[prev - k, node]
        else:
            total += steps[prev - k]
        prev = node
    return total


@pytest.mark.parametrize("k, m", [(0, 3), (1, 0), (3, 1), (4, 3), (5, 2)])
def test_sop_is_optimal_and_keeps_the_zone_order(k: int, m: int) -> None:
    rng = np.random.default_rng(k * 10 + m)
    for _ in range(5):
        start = rng.uniform(1, 10, k + 1)
        ff = rng.uniform(1, 10, (k, k))
        fz = rng.uniform(1, 10, (k, m))
        zf = rng.uniform(1, 10, (m, k))
        steps = rng.uniform(1, 10, max(m - 1, 0))
        order = [int(x) for x in solve_sop(start, ff, fz, zf, steps)]
        assert sorted(order) == list(range(k + m))
        zones = [n for n in order if n >= k]
        assert zones == sorted(zones)
        best = math.inf
        for perm in itertools.permutations(range(k + m)):
            if [n for n in perm if n >= k] == list(range(k, k + m)):
                best = min(best, _order_cost(list(perm), k, start, ff, fz, zf, steps))
        assert _order_cost(order, k, start, ff, fz, zf, steps) == pytest.approx(best)


def test_sop_refuses_bad_input() -> None:
    with pytest.raises(ValueError, match="at most"):
        k = MAX_FRONTIERS + 1
        solve_sop(np.ones(k + 1), np.ones((k, k)), np.ones((k, 1)), np.ones((1, k)), [])
    with pytest.raises(ValueError, match="finite"):
        solve_sop([1.0, np.inf], [[0.0]], [[1.0]], [[1.0]], [])
    with pytest.raises(ValueError, match="zone_steps"):
        solve_sop([1.0, 1.0], [[0.0]], [[1.0, 1.0]], [[1.0], [1.0]], [1.0, 2.0])


def test_first_of_cheapest_matches_brute_force() -> None:
    rng = np.random.default_rng(3)
    sizes = [3, 4, 2]
    first = rng.uniform(0, 5, sizes[0])
    steps = [rng.uniform(0, 5, (a, b)) for a, b in itertools.pairwise(sizes)]
    end = rng.uniform(0, 5, sizes[-1])
    best = min(itertools.product(*[range(s) for s in sizes]),
               key=lambda p: first[p[0]] + steps[0][p[0], p[1]] + steps[1][p[1], p[2]]
               + end[p[2]])
    assert _first_of_cheapest(first, steps, end) == best[0]
    assert _first_of_cheapest(first, [], None) == int(np.argmin(first))


def test_time_cost_at_rest_is_length_over_speed_or_the_turn() -> None:
    a, b = np.zeros(3), np.array([3.0, 0.0, 0.0])
    assert time_cost(3.0, a, b, 0.0, 0.0, np.zeros(3), DYN) == pytest.approx(2.0)
    # A longer path than the straight line costs by its length; a climb by its height.
    assert time_cost(4.5, a, b, 0.0, 0.0, np.zeros(3), DYN) == pytest.approx(3.0)
    up = np.array([3.0, 0.0, 1.0])
    assert time_cost(3.0, a, up, 0.0, 0.0, np.zeros(3), DYN) == pytest.approx(3.0)
    # A half turn: 0.25 rad while reaching 1 rad/s at 2 rad/s², then the rest at 1 rad/s.
    turn = time_cost(0.0, a, a, 0.0, math.pi, np.zeros(3), DYN)
    assert turn == pytest.approx(0.5 + (math.pi - 0.25))
    small = time_cost(0.0, a, a, 0.0, 0.1, np.zeros(3), DYN)
    assert small == pytest.approx(math.sqrt(2 * 0.1 / 2.0))


def test_time_cost_charges_turning_the_velocity() -> None:
    a, b = np.zeros(3), np.array([3.0, 0.0, 0.0])
    ahead = time_cost(3.0, a, b, 0.0, 0.0, np.array([1.5, 0.0, 0.0]), DYN)
    behind = time_cost(3.0, a, -b, 0.0, 0.0, np.array([1.5, 0.0, 0.0]), DYN)
    assert ahead == pytest.approx(2.0)
    assert behind == pytest.approx(2.0 + 2.0 * 1.5 / 2.5)
