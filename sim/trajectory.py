"""Jerk-limited, time-parameterised trajectories through waypoints, computed with ruckig.

Each leg between consecutive waypoints is a 4-DoF (x, y, z, yaw) ruckig profile from rest to rest
with phase synchronisation, so the translation follows the straight segment exactly: the planner's
collision-checked polyline is the path actually flown. The per-axis limits of a leg are the norm
limits scaled by the leg's direction cosines, which bounds the norms of velocity, acceleration and
jerk by the vehicle limits.

`plan_trajectory_from` starts instead from a moving state (for planners that replan in flight):
its first leg cannot follow a straight segment, since the vehicle's velocity need not point at
the first waypoint, so the framework checks that leg by sampling it (`Trajectory.positions`).

`stop_trajectory` brings a moving state to rest as fast as the limits allow, for a flight whose
path the map no longer clears.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from ruckig import ControlInterface, InputParameter, Result, Ruckig, Synchronization
from ruckig import Trajectory as RuckigTrajectory

from sim.geometry import FloatArray, wrap_angle
from sim.vehicle import VehicleLimits

# Ruckig rejects a zero limit; an axis that does not move gets this instead.
_MIN_LIMIT = 1e-6
# Share of the limits every axis keeps on a leg that starts moving (before normalisation).
_AXIS_FLOOR = 0.25


class TrajectoryError(ValueError):
    """The waypoints cannot be turned into a trajectory (NaN, or ruckig failed)."""


@dataclass(frozen=True)
class TrajectorySample:
    """Reference state at one time.

    Attributes:
        position: (3,) m.  velocity: (3,) m/s.  acceleration: (3,) m/s².
        yaw: rad (unwrapped).  yaw_rate: rad/s.
    """

    position: FloatArray
    velocity: FloatArray
    acceleration: FloatArray
    yaw: float
    yaw_rate: float


class Trajectory:
    """A sequence of rest-to-rest legs through every waypoint."""

    def __init__(self, legs: list[RuckigTrajectory], waypoints: FloatArray,
                 curved_first_leg: bool = False) -> None:
        self._legs = legs
        self.waypoints = waypoints
        # True when the first leg starts moving (`plan_trajectory_from`, `stop_trajectory`): it
        # need not follow the segment to its waypoint.
        self.curved_first_leg = curved_first_leg
        durations = np.array([leg.duration for leg in legs], dtype=np.float64)
        self.leg_end_times = np.cumsum(durations)
        # The same times as Python floats: `sample` runs at every physics step, where
        # `bisect` on a list costs a fraction of NumPy's `searchsorted` on one time.
        self._leg_ends: list[float] = self.leg_end_times.tolist()
        self.duration = float(self.leg_end_times[-1]) if legs else 0.0

    @property
    def leg_count(self) -> int:
        return len(self._legs)

    def leg_index(self, t: float) -> int:
        """Index of the leg active at time t (clamped)."""
        return min(bisect.bisect_right(self._leg_ends, t), len(self._legs) - 1)

    def positions(self, until: float, dt: float, start: float = 0.0) -> FloatArray:
        """(K, 3) reference positions every `dt` seconds from `start` to `until` (both clamped
        to the duration), both ends included."""
        end = min(max(until, 0.0), self.duration)
        first = min(max(start, 0.0), end)
        times = np.append(np.arange(first, end, dt), end)
        return np.array([self.sample(float(t)).position for t in times])

    def sample(self, t: float) -> TrajectorySample:
        """Reference state at time t seconds from the start (clamped to [0, duration])."""
        t = min(max(t, 0.0), self.duration)
        i = self.leg_index(t)
        start = self._leg_ends[i - 1] if i > 0 else 0.0
        pos, vel, acc = self._legs[i].at_time(min(t - start, self._legs[i].duration))
        return TrajectorySample(
            position=np.array(pos[:3]),
            velocity=np.array(vel[:3]),
            acceleration=np.array(acc[:3]),
            yaw=float(pos[3]),
            yaw_rate=float(vel[3]),
        )


def _check_waypoints(waypoints: npt.ArrayLike) -> FloatArray:
    wps = np.asarray(waypoints, dtype=np.float64)
    if wps.ndim != 2 or wps.shape[1] != 4 or wps.shape[0] == 0:
        raise TrajectoryError(f"waypoints must have shape (N, 4), got {wps.shape}")
    if not np.all(np.isfinite(wps)):
        raise TrajectoryError("waypoints must be finite")
    return wps


def _short_yaw(current_yaw: float, waypoint: FloatArray) -> FloatArray:
    """The waypoint with its yaw unwrapped next to `current_yaw` (the short way round)."""
    target = waypoint.copy()
    target[3] = current_yaw + wrap_angle(waypoint[3] - current_yaw)
    return target


def plan_trajectory(
    start: npt.ArrayLike, waypoints: npt.ArrayLike, limits: VehicleLimits
) -> Trajectory:
    """Trajectory from `start` (at rest) through every waypoint, stopping at each.

    Args:
        start: (4,) x, y, z, yaw of the vehicle at rest.
        waypoints: (N, 4) x, y, z, yaw; N >= 1. Yaw is taken the short way round.
    """
    start_arr = np.asarray(start, dtype=np.float64)
    if start_arr.shape != (4,):
        raise TrajectoryError(f"start must have shape (4,), got {start_arr.shape}")
    wps = _check_waypoints(waypoints)
    if not np.all(np.isfinite(start_arr)):
        raise TrajectoryError("waypoints must be finite")
    otg = Ruckig(4)
    legs: list[RuckigTrajectory] = []
    current = start_arr.copy()
    for wp in wps:
        target = _short_yaw(float(current[3]), wp)
        legs.append(_leg(otg, current, target, limits))
        current = target
    return Trajectory(legs, wps)


def plan_trajectory_from(
    state: TrajectorySample, waypoints: npt.ArrayLike, limits: VehicleLimits
) -> Trajectory:
    """Trajectory from a moving reference `state` through every waypoint, stopping at each.

    The first leg starts with the state's velocity, acceleration and yaw rate; the following
    legs are straight rest-to-rest legs as in `plan_trajectory`.
    """
    wps = _check_waypoints(waypoints)
    start, moving, accel = _moving_state(state)
    otg = Ruckig(4)
    first = _short_yaw(float(start[3]), wps[0])
    legs = [_moving_leg(otg, start, moving, accel, first, limits)]
    current = first
    for wp in wps[1:]:
        target = _short_yaw(float(current[3]), wp)
        legs.append(_leg(otg, current, target, limits))
        current = target
    return Trajectory(legs, wps, curved_first_leg=True)


def stop_trajectory(state: TrajectorySample, limits: VehicleLimits) -> Trajectory:
    """The quickest jerk-limited stop from a moving reference `state`: velocity, acceleration
    and yaw rate brought to zero, the path going on where the motion carries it.

    Its one waypoint is where the vehicle comes to rest.
    """
    start, moving, accel = _moving_state(state)
    speed = float(np.linalg.norm(moving[:3]))
    heading = np.abs(moving[:3]) / speed if speed > 1e-9 else np.zeros(3)
    weights = _axis_weights(heading, moving[:3], accel[:3], limits)
    inp = InputParameter(4)
    inp.control_interface = ControlInterface.Velocity
    inp.current_position = start.tolist()
    inp.current_velocity = moving.tolist()
    inp.current_acceleration = accel.tolist()
    inp.target_velocity = [0.0, 0.0, 0.0, 0.0]
    inp.target_acceleration = [0.0, 0.0, 0.0, 0.0]
    _set_limits(inp, weights, limits)
    # Phase synchronisation keeps a straight flight braking on its line; ruckig falls back to
    # time synchronisation when the motion is not along one line.
    inp.synchronization = Synchronization.Phase
    traj = RuckigTrajectory(4)
    result = Ruckig(4).calculate(inp, traj)
    if result not in (Result.Working, Result.Finished):
        raise TrajectoryError(f"ruckig could not stop from {start.tolist()}: {result}")
    end, _, _ = traj.at_time(traj.duration)
    return Trajectory([traj], np.array([end], dtype=np.float64), curved_first_leg=True)


def _moving_state(state: TrajectorySample) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(4,) position and yaw, (4,) velocity and yaw rate, (4,) acceleration (yaw: 0) of a
    moving state, checked finite."""
    start = np.array([*state.position, state.yaw], dtype=np.float64)
    moving = np.array([*state.velocity, state.yaw_rate], dtype=np.float64)
    accel = np.array([*state.acceleration, 0.0], dtype=np.float64)
    if not (np.all(np.isfinite(start)) and np.all(np.isfinite(moving))
            and np.all(np.isfinite(accel))):
        raise TrajectoryError("the start state must be finite")
    return start, moving, accel


def _set_limits(inp: InputParameter, weights: FloatArray, limits: VehicleLimits) -> None:
    """Per-axis limits of a 4-DoF input: the translation norm limits times `weights` (3,), each
    at least ruckig's smallest, and the yaw limits as they are."""
    inp.max_velocity = [*np.maximum(limits.v_max * weights, _MIN_LIMIT), limits.yaw_rate_max]
    inp.max_acceleration = [*np.maximum(limits.a_max * weights, _MIN_LIMIT), limits.yaw_acc_max]
    inp.max_jerk = [*np.maximum(limits.j_max * weights, _MIN_LIMIT), limits.yaw_jerk_max]


def _axis_weights(
    direction: FloatArray, velocity: FloatArray, acceleration: FloatArray,
    limits: VehicleLimits,
) -> FloatArray:
    """(3,) unit vector of per-axis shares of the norm limits for a leg that starts moving.

    It leans toward `direction` (of the leg, (3,) absolute direction cosines), the current
    velocity and the current acceleration, plus a floor on every axis: an axis with almost no
    limit but some motion left to undo would take ruckig minutes to settle.
    """
    speed = float(np.linalg.norm(velocity))
    vel_dir = np.abs(velocity) / speed if speed > 1e-9 else np.zeros(3)
    accel = float(np.linalg.norm(acceleration))
    acc_dir = np.abs(acceleration) / accel if accel > 1e-9 else np.zeros(3)
    blend = (direction + min(speed / limits.v_max, 1.0) * vel_dir
             + min(accel / limits.a_max, 1.0) * acc_dir + _AXIS_FLOOR)
    norm = float(np.linalg.norm(blend))
    weights: FloatArray = blend / norm if norm > 1e-12 else np.full(3, 1.0 / np.sqrt(3.0))
    return weights


def _moving_leg(
    otg: Ruckig, start: FloatArray, velocity: FloatArray, acceleration: FloatArray,
    target: FloatArray, limits: VehicleLimits,
) -> RuckigTrajectory:
    """A leg from a moving state to rest at `target`, time-synchronised.

    Per-axis limits are the norm limits times the components of a unit vector, so the norms
    stay within the vehicle limits (`_axis_weights`). An axis whose current velocity or
    acceleration exceeds its limit is braked back into it by ruckig.
    """
    delta = target[:3] - start[:3]
    length = float(np.linalg.norm(delta))
    leg_dir = np.abs(delta) / length if length > 1e-9 else np.zeros(3)
    weights = _axis_weights(leg_dir, velocity[:3], acceleration[:3], limits)
    inp = InputParameter(4)
    inp.current_position = start.tolist()
    inp.current_velocity = velocity.tolist()
    inp.current_acceleration = acceleration.tolist()
    inp.target_position = target.tolist()
    _set_limits(inp, weights, limits)
    inp.synchronization = Synchronization.Time
    traj = RuckigTrajectory(4)
    result = otg.calculate(inp, traj)
    if result not in (Result.Working, Result.Finished):
        raise TrajectoryError(f"ruckig could not reach {target.tolist()}: {result}")
    return traj


def _leg(
    otg: Ruckig, start: FloatArray, target: FloatArray, limits: VehicleLimits
) -> RuckigTrajectory:
    delta = target[:3] - start[:3]
    length = float(np.linalg.norm(delta))
    cosines = np.abs(delta) / length if length > 1e-9 else np.zeros(3)
    inp = InputParameter(4)
    inp.current_position = start.tolist()
    inp.target_position = target.tolist()
    _set_limits(inp, cosines, limits)
    inp.synchronization = Synchronization.Phase
    traj = RuckigTrajectory(4)
    result = otg.calculate(inp, traj)
    if result not in (Result.Working, Result.Finished):
        raise TrajectoryError(f"ruckig could not reach {target.tolist()}: {result}")
    return traj
