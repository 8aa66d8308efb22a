"""The coverage path's ATSP solver: `planners/tour.py` against LKH-3 (`elkai`) and OR-Tools'
routing solver, on tour length and time for 10-200 nodes.

    .venv/bin/pip install elkai ortools   # only for this comparison
    .venv/bin/python benchmarks/falcon_tour_solvers.py [--sizes 10 20 50 100 200] [--instances 5]

Instances are FALCON's: random zone positions in a 40 x 40 x 3 m box, costs the straight-line
time at 1.5 m/s times a random detour factor of 1-1.5 per ordered pair (asymmetric), an open
path from node 0 (column 0 zero). Each solver's tour length is divided by the best any of them
found on that instance; times are per solve, one thread. A solver that is not installed is
reported as such. Writes `results/falcon_tour_solvers.json`.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks.common import print_table, write_json
from planners.tour import solve_atsp, tour_cost

FloatArray = npt.NDArray[np.float64]
Solver = Callable[[FloatArray], list[int]]


def instance(n: int, rng: np.random.Generator) -> FloatArray:
    points = rng.uniform([0.0, 0.0, 0.0], [40.0, 40.0, 3.0], (n, 3))
    dist = np.linalg.norm(points[:, None] - points[None], axis=2) / 1.5
    cost: FloatArray = dist * rng.uniform(1.0, 1.5, (n, n))
    np.fill_diagonal(cost, 0.0)
    cost[:, 0] = 0.0
    return cost


def _ours(cost: FloatArray) -> list[int]:
    return [int(i) for i in solve_atsp(cost)]


def _elkai() -> Solver | None:
    try:
        import elkai
    except ImportError:
        return None

    def solve(cost: FloatArray) -> list[int]:
        # LKH takes integers: centiseconds, as FALCON's code scales its matrix by 100.
        matrix = np.rint(cost * 100.0).astype(int).tolist()
        tour = elkai.DistanceMatrix(matrix).solve_tsp(runs=1)
        return [int(i) for i in tour[:-1]]
    return solve


def _ortools() -> Solver | None:
    try:
        from ortools.constraint_solver import pywrapcp, routing_enums_pb2
    except ImportError:
        return None

    def solve(cost: FloatArray) -> list[int]:
        n = len(cost)
        matrix = np.rint(cost * 100.0).astype(int)
        manager = pywrapcp.RoutingIndexManager(n, 1, 0)
        routing = pywrapcp.RoutingModel(manager)
        arc = routing.RegisterTransitCallback(
            lambda i, j: int(matrix[manager.IndexToNode(i), manager.IndexToNode(j)]))
        routing.SetArcCostEvaluatorOfAllVehicles(arc)
        params = pywrapcp.DefaultRoutingSearchParameters()
        params.first_solution_strategy = routing_enums_pb2.FirstSolutionStrategy.PATH_CHEAPEST_ARC
        solution = routing.SolveWithParameters(params)
        index, tour = routing.Start(0), []
        while not routing.IsEnd(index):
            tour.append(manager.IndexToNode(index))
            index = solution.Value(routing.NextVar(index))
        return tour
    return solve


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[10, 20, 50, 100, 200])
    parser.add_argument("--instances", type=int, default=5)
    args = parser.parse_args()
    solvers: dict[str, Solver | None] = {"planners/tour.py": _ours, "elkai (LKH-3, 1 run)":
                                         _elkai(), "OR-Tools (cheapest arc + local search)":
                                         _ortools()}
    _ours(instance(20, np.random.default_rng(0)))  # compile the numba kernels first
    rows: list[dict[str, Any]] = []
    for n in args.sizes:
        rng = np.random.default_rng(n)
        found: dict[str, list[tuple[float, float]]] = {k: [] for k, s in solvers.items() if s}
        for _ in range(args.instances):
            cost = instance(n, rng)
            lengths: dict[str, tuple[float, float]] = {}
            for name, solver in solvers.items():
                if solver is None:
                    continue
                t0 = time.perf_counter()
                tour = solver(cost)
                ms = (time.perf_counter() - t0) * 1000.0
                assert sorted(tour) == list(range(n)), name
                lengths[name] = (tour_cost(cost, tour), ms)
            best = min(v[0] for v in lengths.values())
            for name, (length, ms) in lengths.items():
                found[name].append((length / best, ms))
        for name, vals in found.items():
            ratio = np.array([v[0] for v in vals])
            ms = np.array([v[1] for v in vals])
            rows.append({"nodes": n, "solver": name, "length_over_best_mean": float(ratio.mean()),
                         "length_over_best_max": float(ratio.max()),
                         "ms_median": float(np.median(ms)), "ms_max": float(ms.max())})
    missing = [name for name, s in solvers.items() if s is None]
    print_table("ATSP tours (open path from node 0), tour length / best of the solvers",
                ["nodes", "solver", "length/best mean", "max", "ms median", "ms max"],
                [[r["nodes"], r["solver"], f"{r['length_over_best_mean']:.3f}",
                  f"{r['length_over_best_max']:.3f}", f"{r['ms_median']:.1f}",
                  f"{r['ms_max']:.1f}"] for r in rows])
    for name in missing:
        print(f"{name}: not installed")
    path = write_json("falcon_tour_solvers", {"rows": rows, "not_installed": missing,
                                              "instances": args.instances})
    print(f"\nwritten {path}")


if __name__ == "__main__":
    main()
