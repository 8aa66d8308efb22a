"""FALCON's coverage path over the zones and the frontier ordering it guides (Zhang et al.,
T-RO 2024, Sec. V; the public code's `calculateCostMatrixSingleThread` and
`planExploreMotionHGrid`).

- **Lengths** between points standing in zones: the straight line when it is at most
  `hybrid_radius_m` long and crosses no occupied voxel (the code's straight-line try before its
  A* through free and unknown space), otherwise the way along the connectivity graph (from each
  point to its zone's centre, then centre to centre); 1000 m more than the straight line when
  the graph does not join them (the code's unreachable cost).
- **Coverage path**: an asymmetric TSP from the vehicle over the active free zones (those
  holding frontier viewpoints, placed at their viewpoint nearest the viewpoints' mean) and the
  unknown zones, costed by `planners.falcon_costs.time_cost`, multiplied by
  `unknown_penalty` when an unknown zone is involved; the vehicle's leg to an unknown zone costs
  1000 s more (the code: the next zone should not be unknown); returning is free (open path).
- **Ordering**: a sequential ordering problem (`planners.falcon_sop`) over the frontiers of the
  coverage path's first zone and of the vehicle's own cell, and the rest of the coverage path,
  whose order is kept.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from planners.falcon_costs import Dynamics, time_cost
from planners.falcon_zones import Zones
from planners.lines import segments_clear
from planners.search import BoolGrid, IndexArray
from planners.tour import solve_atsp
from sim.map_view import MapView

FloatArray = npt.NDArray[np.float64]

UNREACHABLE_M = 1000.0  # the code's length of a path that was not found
UNKNOWN_FIRST_S = 1000.0  # the code: "next zone should NOT be unknown"


@dataclass(frozen=True)
class CoveragePath:
    """The coverage path after the vehicle.

    Attributes:
        positions: (C, 3) world metres of its nodes, in order.
        zone: (C,) zone id of each node.
        unknown: (C,) whether each node is an unknown zone.
        legs_s: (C,) cost of reaching each node from the one before (the vehicle first).
    """

    positions: FloatArray
    zone: IndexArray
    unknown: npt.NDArray[np.bool_]
    legs_s: FloatArray


def lengths(view: MapView, zones: Zones, passable: BoolGrid, a: FloatArray, za: IndexArray,
            b: FloatArray, zb: IndexArray, radius_m: float) -> FloatArray:
    """(A, B) lengths from the points `a` in zones `za` to `b` in `zb` (see the module)."""
    euclid = np.linalg.norm(a[:, None, :] - b[None, :, :], axis=2)
    graph = np.full(euclid.shape, np.inf)
    ia, ib = za >= 0, zb >= 0
    if ia.any() and ib.any():
        to_a = np.linalg.norm(a[ia] - zones.centers[za[ia]], axis=1)
        to_b = np.linalg.norm(b[ib] - zones.centers[zb[ib]], axis=1)
        sub = zones.distance_m(za[ia], zb[ib]) + to_a[:, None] + to_b[None, :]
        graph[np.ix_(ia, ib)] = sub
    i, j = np.nonzero(euclid <= radius_m)
    clear = segments_clear(view, passable, a[i], b[j]) if len(i) else np.zeros(0, dtype=bool)
    out = graph
    out[i[clear], j[clear]] = euclid[i[clear], j[clear]]
    unreachable = ~np.isfinite(out)
    out[unreachable] = UNREACHABLE_M + euclid[unreachable]
    return out


def coverage_path(view: MapView, zones: Zones, passable: BoolGrid, here: FloatArray,
                  velocity: FloatArray, free_nodes: FloatArray, free_zone: IndexArray,
                  dyn: Dynamics, radius_m: float, unknown_penalty: float,
                  exact_max_nodes: int) -> CoveragePath:
    """The coverage path from `here` over the active free zones (`free_nodes` standing in
    `free_zone`) and every kept unknown zone."""
    unknown_ids = np.flatnonzero(zones.unknown & zones.kept)
    points = np.vstack([free_nodes, zones.centers[unknown_ids]])
    zone = np.concatenate([free_zone, unknown_ids]).astype(np.int64)
    is_unknown = np.concatenate([np.zeros(len(free_zone), dtype=bool),
                                 np.ones(len(unknown_ids), dtype=bool)])
    here_zone = zones.zone_at(view, here[None])
    first_len = lengths(view, zones, passable, here[None], here_zone, points, zone, radius_m)[0]
    first = time_cost(first_len, here, points, 0.0, 0.0, velocity, dyn)
    first[is_unknown] = (UNKNOWN_FIRST_S + np.linalg.norm(points[is_unknown] - here, axis=1)
                         ) * unknown_penalty
    between = time_cost(lengths(view, zones, passable, points, zone, points, zone, radius_m),
                        points[:, None, :], points[None, :, :], 0.0, 0.0, np.zeros(3), dyn)
    between[is_unknown[:, None] | is_unknown[None, :]] *= unknown_penalty
    n = len(points) + 1
    cost = np.zeros((n, n))
    cost[0, 1:] = first
    cost[1:, 1:] = between
    np.fill_diagonal(cost, 0.0)
    order = solve_atsp(cost, exact_max_nodes=exact_max_nodes)[1:] - 1
    legs = cost[np.concatenate([[0], order[:-1] + 1]), order + 1]
    return CoveragePath(points[order], zone[order], is_unknown[order], legs)

