"""The asymmetric TSP solver: exact against brute force on small instances, a near-optimal
local search beyond, and its answers always tours from node 0."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from planners.tour import solve_atsp, tour_cost


def _brute_force(cost: np.ndarray) -> float:
    n = len(cost)
    return min(tour_cost(cost, [0, *p]) for p in itertools.permutations(range(1, n)))


def _is_tour(tour: np.ndarray, n: int) -> bool:
    return tour[0] == 0 and sorted(tour.tolist()) == list(range(n))


def test_tour_cost_closes_the_cycle() -> None:
    cost = np.array([[0.0, 1.0, 9.0], [9.0, 0.0, 2.0], [4.0, 9.0, 0.0]])
    assert tour_cost(cost, [0, 1, 2]) == 1.0 + 2.0 + 4.0
    assert tour_cost(cost, [0, 2, 1]) == 9.0 + 9.0 + 9.0


@pytest.mark.parametrize("n", range(1, 10))
def test_exact_below_the_limit_matches_brute_force(n: int) -> None:
    rng = np.random.default_rng(n)
    for _ in range(6):
        cost = rng.uniform(0.0, 10.0, (n, n))
        tour = solve_atsp(cost)
        assert _is_tour(tour, n)
        assert tour_cost(cost, tour) == pytest.approx(_brute_force(cost), abs=1e-9)


@pytest.mark.parametrize("n", range(1, 9))
def test_local_search_gives_tours(n: int) -> None:
    rng = np.random.default_rng(100 + n)
    cost = rng.uniform(0.0, 10.0, (n, n))
    tour = solve_atsp(cost, exact_max_nodes=0)
    assert _is_tour(tour, n)
    assert tour_cost(cost, tour) >= _brute_force(cost) - 1e-9


def test_local_search_is_near_optimal_on_spatial_instances() -> None:
    # Tour costs like FUEL's: travel distances between points plus an asymmetric part.
    rng = np.random.default_rng(7)
    ratios = []
    for _ in range(25):
        n = 12
        points = rng.uniform(0.0, 10.0, (n, 2))
        cost = np.linalg.norm(points[:, None] - points[None], axis=2)
        cost += rng.uniform(0.0, 1.0, (n, n))
        cost[:, 0] = 0.0  # an open path from node 0, FUEL's encoding
        exact = tour_cost(cost, solve_atsp(cost, exact_max_nodes=12))
        heuristic = tour_cost(cost, solve_atsp(cost, exact_max_nodes=0))
        assert heuristic >= exact - 1e-9
        ratios.append(heuristic / exact)
    assert np.mean(ratios) < 1.03
    assert np.max(ratios) < 1.15


def test_local_search_improves_on_a_bad_nearest_neighbour_tour() -> None:
    # Points on a line, start at one end: the greedy order is optimal for the open path, and
    # the returned tour must be at least as good as it.
    n = 30
    x = np.arange(n, dtype=np.float64)
    cost = np.abs(x[:, None] - x[None])
    cost[:, 0] = 0.0
    tour = solve_atsp(cost)
    assert _is_tour(tour, n)
    assert tour_cost(cost, tour) == pytest.approx(n - 1)


def test_large_instance_is_a_tour() -> None:
    rng = np.random.default_rng(3)
    cost = rng.uniform(0.0, 10.0, (80, 80))
    tour = solve_atsp(cost)
    assert _is_tour(tour, 80)
    # Better than the identity order by a wide margin on random costs.
    assert tour_cost(cost, tour) < 0.5 * tour_cost(cost, np.arange(80))


def test_rejects_bad_matrices() -> None:
    with pytest.raises(ValueError, match="square"):
        solve_atsp(np.zeros((2, 3)))
    with pytest.raises(ValueError, match="finite"):
        solve_atsp(np.array([[0.0, np.inf], [1.0, 0.0]]))
