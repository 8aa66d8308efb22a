"""A flight: the trajectory being flown, and when the planner is asked again."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from sim.occupancy import StateGrid
from sim.trajectory import Trajectory, TrajectorySample, plan_trajectory
from sim.vehicle import VehicleLimits


@dataclass
class Flight:
    """The trajectory being flown and when to ask the planner again.

    Attributes:
        start_time: simulated time the trajectory starts at, s.
        stop_after: seconds into the trajectory where the flight ends (the plan's horizon).
        stop_leg: index of the last leg flown.
        replan_s: ask again this often in flight (None: only at the end).
        next_replan: simulated time of the next mid-flight question.
        checked_on: the map the path was checked against; None for flights the map does not
            guard (the start-up turn in place, a safety stop, safety stops switched off).
        checked_at_update: occupancy updates counted when the path was last checked.
        braking: a safety stop.
    """

    trajectory: Trajectory
    start_time: float
    stop_after: float
    stop_leg: int
    replan_s: float | None = None
    next_replan: float = math.inf
    checked_on: StateGrid | None = None
    checked_at_update: int = 0
    braking: bool = False

    def reference(self, now: float) -> TrajectorySample:
        return self.trajectory.sample(min(now - self.start_time, self.stop_after))

    def finished(self, now: float) -> bool:
        return now - self.start_time >= self.stop_after - 1e-9

    def replan_due(self, now: float) -> bool:
        return now >= self.next_replan - 1e-9 and not self.finished(now)

    def schedule_replan(self, now: float, replan_s: float | None) -> None:
        self.replan_s = replan_s
        self.next_replan = now + replan_s if replan_s is not None else math.inf

    def end_state(self) -> TrajectorySample:
        """Where the flight comes to rest, at rest."""
        end = self.trajectory.sample(self.stop_after)
        return TrajectorySample(end.position, np.zeros(3), np.zeros(3), end.yaw, 0.0)


def hold_at(rest: npt.NDArray[np.float64]) -> TrajectorySample:
    """Hovering at rest at (4,) x, y, z, yaw."""
    return TrajectorySample(rest[:3].copy(), np.zeros(3), np.zeros(3), float(rest[3]), 0.0)


def startup_spin(rest: npt.NDArray[np.float64], now: float, limits: VehicleLimits) -> Flight:
    """One turn in place before the first plan, so that every planner starts from the same
    all-round view instead of a single frustum."""
    turns = rest[None].repeat(4, axis=0)
    turns[:, 3] = rest[3] + np.pi / 2.0 * np.arange(1, 5)
    traj = plan_trajectory(rest, turns, limits)
    return Flight(traj, now, traj.duration, traj.leg_count - 1)
