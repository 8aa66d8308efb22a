"""The safety monitor: a flight brakes when the map finds an obstacle by the rest of its path.

Thin surfaces seen from afar can be cleared from the map by the rays that pass them and found
again nearer, on a path already accepted, so the map is not trusted only once, when the plan is
checked: every occupancy update while a plan is flown checks the rest of its path against the
map the plan was checked on.
"""

from __future__ import annotations

import time

import numpy as np
import numpy.typing as npt

from sim.config import EpisodeConfig
from sim.flight import Flight
from sim.map_view import MappingStack
from sim.search_checks import path_meets_new_obstacle
from sim.stage_costs import StageCosts
from sim.trajectory import TrajectoryError, stop_trajectory


class SafetyMonitor:
    """Guards flights against obstacles found after their plan was checked."""

    def __init__(self, config: EpisodeConfig, mapping: MappingStack, costs: StageCosts) -> None:
        self.cfg, self.mapping, self.costs = config, mapping, costs

    def guard(self, flight: Flight, occupancy_updates: int) -> None:
        """Keep the map `flight` was checked on (when the preset turns safety stops on)."""
        if not self.cfg.safety_stops:
            return
        t0 = time.perf_counter()
        flight.checked_on = self.mapping.occupancy.copy_state()
        flight.checked_at_update = occupancy_updates
        self.costs.checks += time.perf_counter() - t0

    def newly_blocked(self, flight: Flight, now: float, occupancy_updates: int) -> bool:
        """Whether an occupancy update since the last look found an obstacle the vehicle could
        touch on the rest of the flight's path."""
        if flight.checked_on is None or flight.checked_at_update == occupancy_updates:
            return False
        flight.checked_at_update = occupancy_updates
        t0 = time.perf_counter()
        occ = self.mapping.occupancy
        # Only what the vehicle could touch: a voxel's cube within its radius of the path;
        # stopping for everything within the safety radius would stop flights for walls beside
        # the path.
        reach = self.cfg.limits.radius_m
        blocked = path_meets_new_obstacle(occ.state, flight.checked_on, occ.origin,
                                          occ.voxel_size, reach, self.rest_of_path(flight, now))
        self.costs.checks += time.perf_counter() - t0
        return blocked

    def rest_of_path(self, flight: Flight, now: float) -> npt.NDArray[np.float64]:
        """(K, 3) the path still to fly: the reference position, then samples of a curved first
        leg (no more than half a voxel apart) and the waypoints ending the straight legs."""
        traj = flight.trajectory
        t = now - flight.start_time
        leg = min(traj.leg_index(t), flight.stop_leg)
        parts = [flight.reference(now).position[None]]
        if leg == 0 and traj.curved_first_leg:
            dt = 0.5 * self.mapping.occupancy.voxel_size / self.cfg.limits.v_max
            parts.append(traj.positions(float(traj.leg_end_times[0]), dt, start=t))
            leg = 1
        parts.append(traj.waypoints[leg:flight.stop_leg + 1, :3])
        return np.vstack(parts)

    def stop(self, flight: Flight, now: float) -> Flight | None:
        """A flight braking from the current reference state as fast as the limits allow;
        None when no stop can be planned from this state (the flight then goes on)."""
        try:
            stop = stop_trajectory(flight.reference(now), self.cfg.limits)
        except TrajectoryError:
            return None
        return Flight(stop, now, stop.duration, 0, braking=True)
