"""The framework's check of a plan: shape, bounds, traversable path, a flyable trajectory.

A plan is cut at its first waypoint that cannot be reached through traversable (or, from
outside traversable space, known free) voxels; the rest is time-parameterised with ruckig
within the vehicle's limits. From a moving state the first leg is a curve, checked by its
samples.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from areas.area import Area
from sim.config import EpisodeConfig
from sim.flight import Flight
from sim.interface import Plan, PlanOutcome
from sim.map_view import BoolGrid, MappingStack, MapView
from sim.search_checks import plan_is_clear, starts_traversable
from sim.trajectory import (
    Trajectory,
    TrajectoryError,
    TrajectorySample,
    plan_trajectory,
    plan_trajectory_from,
)

Start = npt.NDArray[np.float64] | TrajectorySample


def _free_mask(view: MapView, here: npt.NDArray[np.float64]) -> BoolGrid:
    """The known-free mask `plan_is_clear` needs for legs from `here`: read only when `here` is
    not traversable, so the traversable mask stands in otherwise (the free mask is a pass over
    the whole grid, made per view)."""
    if starts_traversable(view.traversable, view.origin, view.voxel_size, here):
        return view.traversable
    return view.free


class PlanChecker:
    """Turns a planner's `Plan` into a `Flight`, or says why it cannot be flown."""

    def __init__(self, area: Area, config: EpisodeConfig, mapping: MappingStack) -> None:
        self.area, self.cfg, self.mapping = area, config, mapping

    def _valid(self, plan: Plan, wps: npt.NDArray[np.float64]) -> bool:
        if wps.ndim != 2 or wps.shape[1:] != (4,) or len(wps) == 0 or not np.all(np.isfinite(wps)):
            return False
        inside = np.all((wps[:, :3] >= self.area.bounds_min) &
                        (wps[:, :3] <= self.area.bounds_max), axis=1)
        replan = plan.replan_s
        return bool(np.all(inside)) and (replan is None or (math.isfinite(replan) and replan > 0))

    def check(self, plan: Plan, start: Start, now: float) -> tuple[
        Flight | None, PlanOutcome, npt.NDArray[np.float64]
    ]:
        """Check, cut and time-parameterise `plan`. `start` is (4,) x, y, z, yaw at rest, or
        the moving reference state of a flight interrupted by `Plan.replan_s`. Returns the
        flight (None if rejected), the outcome the planner sees, and the waypoints accepted."""
        wps = np.asarray(plan.waypoints, dtype=np.float64)
        if not self._valid(plan, wps):
            return None, PlanOutcome.INVALID, wps
        view = self.mapping.view()
        moving = isinstance(start, TrajectorySample)
        here = start.position if isinstance(start, TrajectorySample) else start[:3]
        clear = plan_is_clear(view.traversable, _free_mask(view, here), view.origin,
                              view.voxel_size, here, wps[:, :3])
        if clear == 0:
            return None, PlanOutcome.BLOCKED, wps
        wps = wps[:clear]
        try:
            if isinstance(start, TrajectorySample):
                traj = plan_trajectory_from(start, wps, self.cfg.limits)
            else:
                traj = plan_trajectory(start, wps, self.cfg.limits)
        except TrajectoryError:
            return None, PlanOutcome.INVALID, wps
        if moving and not self._first_leg_clear(traj, here):
            return None, PlanOutcome.BLOCKED, wps
        stop_leg = traj.leg_count - 1
        if plan.horizon_s is not None:
            stop_leg = min(int(np.searchsorted(traj.leg_end_times, plan.horizon_s - 1e-9)),
                           traj.leg_count - 1)
        outcome = PlanOutcome.REACHED if clear == len(plan.waypoints) else PlanOutcome.BLOCKED
        flight = Flight(traj, now, float(traj.leg_end_times[stop_leg]), stop_leg)
        flight.schedule_replan(now, plan.replan_s)
        return flight, outcome, wps

    def _first_leg_clear(self, traj: Trajectory, here: npt.NDArray[np.float64]) -> bool:
        """The first leg from a moving state is a curve: check it by its samples, close enough
        (at most half a voxel apart) that the segments between them stand for it. A vehicle
        outside traversable space may cross known free voxels to get back in, as from rest,
        but at speed only within one safety radius of where it is."""
        view = self.mapping.view()
        dt = 0.5 * view.voxel_size / self.cfg.limits.v_max
        samples = np.vstack([here[None], traj.positions(float(traj.leg_end_times[0]), dt)])
        idx = view.world_to_index(samples)
        if not np.all(view.in_bounds(idx)):
            return False
        entered = np.flatnonzero(view.traversable[idx[:, 0], idx[:, 1], idx[:, 2]])
        if len(entered) == 0:
            return False
        first = int(entered[0])
        escape = float(np.sum(np.linalg.norm(np.diff(samples[: first + 1], axis=0), axis=1)))
        if escape > self.cfg.safety_radius_m:
            return False
        return plan_is_clear(view.traversable, _free_mask(view, here), view.origin,
                             view.voxel_size, here, samples[1:]) == len(samples) - 1
