"""Jerk-limited trajectories: limits on norms, rest at every waypoint, straight legs, short yaw."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pytest

from sim.geometry import wrap_angle
from sim.trajectory import (
    Trajectory,
    TrajectoryError,
    TrajectorySample,
    plan_trajectory,
    plan_trajectory_from,
    stop_trajectory,
)
from sim.vehicle import VehicleLimits

FloatArray = npt.NDArray[np.float64]

LIMITS = VehicleLimits()
DT = 0.002
START = np.array([0.0, 0.0, 1.0, 0.0])
# Diagonal 3D legs, a leg along one axis, a pure yaw turn across +-pi, and yaw with translation.
WAYPOINTS = np.array(
    [
        [2.0, 1.0, 1.5, 1.0],
        [2.0, 3.5, 1.0, -2.5],
        [-1.0, 3.5, 2.0, 3.0],
        [-1.0, 3.5, 2.0, -3.0],
        [0.5, 0.2, 0.8, 0.0],
    ]
)


@dataclass
class Samples:
    t: FloatArray
    position: FloatArray
    velocity: FloatArray
    acceleration: FloatArray
    yaw: FloatArray
    yaw_rate: FloatArray


def sample_densely(traj: Trajectory, dt: float = DT) -> Samples:
    t = np.arange(0.0, traj.duration + dt, dt)
    s = [traj.sample(float(ti)) for ti in t]
    return Samples(
        t=t,
        position=np.array([x.position for x in s]),
        velocity=np.array([x.velocity for x in s]),
        acceleration=np.array([x.acceleration for x in s]),
        yaw=np.array([x.yaw for x in s]),
        yaw_rate=np.array([x.yaw_rate for x in s]),
    )


@pytest.fixture(scope="module")
def traj() -> Trajectory:
    return plan_trajectory(START, WAYPOINTS, LIMITS)


@pytest.fixture(scope="module")
def samples(traj: Trajectory) -> Samples:
    return sample_densely(traj)


def test_structure(traj: Trajectory) -> None:
    assert traj.leg_count == len(WAYPOINTS)
    assert traj.leg_end_times.shape == (len(WAYPOINTS),)
    assert np.all(np.diff(traj.leg_end_times) > 0.0)
    assert traj.duration == traj.leg_end_times[-1]
    assert np.array_equal(traj.waypoints, WAYPOINTS)
    # A 3 m leg at 1.5 m/s cannot take less than 2 s; the whole path is ~16 m.
    lengths = np.linalg.norm(np.diff(np.vstack([START, WAYPOINTS])[:, :3], axis=0), axis=1)
    durations = np.diff(np.concatenate([[0.0], traj.leg_end_times]))
    assert np.all(durations >= lengths / LIMITS.v_max)
    assert traj.duration < 2.0 * lengths.sum() / LIMITS.v_max + 10.0


def test_velocity_acceleration_and_yaw_rate_limits(samples: Samples) -> None:
    tol = 1e-6
    speed = np.linalg.norm(samples.velocity, axis=1)
    accel = np.linalg.norm(samples.acceleration, axis=1)
    assert speed.max() <= LIMITS.v_max * (1 + tol)
    assert accel.max() <= LIMITS.a_max * (1 + tol)
    assert np.abs(samples.yaw_rate).max() <= LIMITS.yaw_rate_max * (1 + tol)
    # The limits are actually reached on the long legs (not a trivially slow trajectory).
    assert speed.max() > 0.99 * LIMITS.v_max
    assert accel.max() > 0.99 * LIMITS.a_max


def test_jerk_and_yaw_acceleration_limits(samples: Samples) -> None:
    # Differences of a piecewise-polynomial profile average the derivative over a step; by
    # convexity the average of bounded vectors is bounded by the same norm.
    jerk = np.linalg.norm(np.diff(samples.acceleration, axis=0), axis=1) / DT
    assert jerk.max() <= LIMITS.j_max * (1 + 1e-6) + 1e-6
    assert jerk.max() > 0.9 * LIMITS.j_max
    yaw_acc = np.abs(np.diff(samples.yaw_rate)) / DT
    assert yaw_acc.max() <= LIMITS.yaw_acc_max * (1 + 1e-6) + 1e-6


def test_derivatives_are_consistent(samples: Samples) -> None:
    # Central differences of position and yaw reproduce velocity and yaw rate.
    v_fd = (samples.position[2:] - samples.position[:-2]) / (2 * DT)
    assert np.abs(v_fd - samples.velocity[1:-1]).max() < 1e-4
    a_fd = (samples.velocity[2:] - samples.velocity[:-2]) / (2 * DT)
    assert np.abs(a_fd - samples.acceleration[1:-1]).max() < 0.02  # jerk * DT
    yr_fd = (samples.yaw[2:] - samples.yaw[:-2]) / (2 * DT)
    assert np.abs(yr_fd - samples.yaw_rate[1:-1]).max() < 1e-4


def test_passes_through_every_waypoint_at_rest(traj: Trajectory) -> None:
    for i, (t_end, wp) in enumerate(zip(traj.leg_end_times, WAYPOINTS, strict=True)):
        for t in (float(t_end), float(t_end) - 1e-12):
            s = traj.sample(t)
            assert s.position == pytest.approx(wp[:3], abs=1e-9), f"leg {i}"
            assert np.linalg.norm(s.velocity) < 1e-9
            assert np.linalg.norm(s.acceleration) < 1e-9
            assert wrap_angle(s.yaw) == pytest.approx(wrap_angle(wp[3]), abs=1e-9)
            assert abs(s.yaw_rate) < 1e-9
        # Between waypoints the vehicle moves.
        mid = traj.leg_end_times[i] - 0.5 * (
            traj.leg_end_times[i] - (traj.leg_end_times[i - 1] if i else 0.0)
        )
        assert np.linalg.norm(traj.sample(float(mid)).velocity) > 0.1 or i == 3


def test_sample_is_clamped_to_the_trajectory(traj: Trajectory) -> None:
    before = traj.sample(-5.0)
    assert before.position == pytest.approx(START[:3], abs=1e-12)
    assert before.yaw == pytest.approx(START[3], abs=1e-12)
    assert np.linalg.norm(before.velocity) == 0.0
    after = traj.sample(traj.duration + 100.0)
    assert after.position == pytest.approx(WAYPOINTS[-1, :3], abs=1e-9)
    assert np.linalg.norm(after.velocity) < 1e-9
    assert isinstance(after, TrajectorySample)


def test_each_leg_is_a_straight_segment(traj: Trajectory, samples: Samples) -> None:
    corners = np.vstack([START, WAYPOINTS])[:, :3]
    starts = np.concatenate([[0.0], traj.leg_end_times[:-1]])
    for i, (t0, t1) in enumerate(zip(starts, traj.leg_end_times, strict=True)):
        a, b = corners[i], corners[i + 1]
        in_leg = (samples.t >= t0) & (samples.t <= t1)
        p = samples.position[in_leg]
        assert len(p) > 10
        seg = b - a
        length = float(np.linalg.norm(seg))
        if length == 0.0:
            assert np.abs(p - a).max() < 1e-12  # pure yaw turn: the position does not move
            continue
        rel = p - a
        s = rel @ seg / length**2
        off_line = np.linalg.norm(rel - s[:, None] * seg[None, :], axis=1)
        assert off_line.max() < 1e-9
        # Monotone from one end to the other, no overshoot.
        assert s.min() > -1e-9 and s.max() < 1 + 1e-9
        assert np.all(np.diff(s) > -1e-12)
        # The velocity is parallel to the segment.
        v = samples.velocity[in_leg]
        assert np.linalg.norm(np.cross(v, seg), axis=1).max() < 1e-9 * length + 1e-12


def test_yaw_takes_the_short_way_round() -> None:
    here = [1.0, 1.0, 1.0]
    traj = plan_trajectory([*here, 3.0], [[*here, -3.0]], LIMITS)
    s = sample_densely(traj)
    # From 3.0 through pi to -3.0 (= 2 pi - 3.0 unwrapped): 0.283 rad, not 6 rad through 0.
    assert s.yaw[0] == pytest.approx(3.0)
    assert s.yaw[-1] == pytest.approx(2.0 * np.pi - 3.0, abs=1e-9)
    assert np.all(np.diff(s.yaw) >= -1e-12)
    wrapped = np.array([wrap_angle(y) for y in s.yaw])
    assert np.abs(wrapped).min() >= 3.0 - 1e-9
    assert wrap_angle(s.yaw[-1]) == pytest.approx(-3.0, abs=1e-9)
    assert np.abs(s.position - here).max() == 0.0
    # 0.283 rad takes well under the 6.28 rad / 1 rad/s the long way would need.
    assert traj.duration < 1.5
    back = sample_densely(plan_trajectory([*here, -3.0], [[*here, 3.0]], LIMITS))
    assert back.yaw[-1] == pytest.approx(-(2.0 * np.pi - 3.0), abs=1e-9)
    assert np.all(np.diff(back.yaw) <= 1e-12)


def test_yaw_is_continuous_across_legs(samples: Samples) -> None:
    # Unwrapped yaw never jumps, even when the waypoints' yaw crosses +-pi.
    assert np.abs(np.diff(samples.yaw)).max() <= LIMITS.yaw_rate_max * DT * (1 + 1e-6)


def test_single_waypoint_at_the_start_is_a_zero_length_trajectory() -> None:
    traj = plan_trajectory(START, START[None, :], LIMITS)
    assert traj.leg_count == 1
    assert traj.duration == pytest.approx(0.0, abs=1e-9)
    assert traj.sample(0.5).position == pytest.approx(START[:3])


@pytest.mark.parametrize(
    "waypoints",
    [
        np.array([[1.0, 2.0, np.nan, 0.0]]),
        np.array([[1.0, 2.0, 1.0, 0.0], [1.0, np.inf, 1.0, 0.0]]),
        np.array([[1.0, 2.0, 1.0, np.nan]]),
        np.array([1.0, 2.0, 1.0, 0.0]),  # 1-D
        np.zeros((2, 3)),
        np.zeros((0, 4)),
        np.zeros((1, 2, 4)),
    ],
)
def test_bad_waypoints_raise(waypoints: FloatArray) -> None:
    with pytest.raises(TrajectoryError):
        plan_trajectory(START, waypoints, LIMITS)


def test_non_finite_start_raises() -> None:
    with pytest.raises(TrajectoryError):
        plan_trajectory([0.0, np.nan, 1.0, 0.0], WAYPOINTS, LIMITS)
    assert issubclass(TrajectoryError, ValueError)


def test_tighter_limits_slow_the_trajectory_down() -> None:
    slow = VehicleLimits(v_max=0.5, a_max=1.0, j_max=4.0)
    traj = plan_trajectory(START, WAYPOINTS[:2], slow)
    s = sample_densely(traj, dt=0.005)
    assert np.linalg.norm(s.velocity, axis=1).max() <= 0.5 * (1 + 1e-6)
    assert np.linalg.norm(s.acceleration, axis=1).max() <= 1.0 * (1 + 1e-6)
    fast = plan_trajectory(START, WAYPOINTS[:2], LIMITS)
    assert traj.duration > fast.duration


# -- from a moving state ------------------------------------------------------------------------

MOVING = TrajectorySample(
    position=np.array([0.0, 0.0, 1.0]),
    velocity=np.array([1.2, -0.6, 0.1]),
    acceleration=np.array([-0.5, 1.0, 0.0]),
    yaw=0.3,
    yaw_rate=0.4,
)


@pytest.mark.parametrize(
    "waypoints",
    [
        np.array([[3.0, 0.5, 1.0, 0.0]]),  # roughly ahead
        np.array([[-2.0, 1.0, 1.2, 2.5]]),  # behind: the vehicle must turn back
        np.array([[0.3, -0.2, 1.0, 0.3], [1.0, 2.0, 1.5, 1.0]]),  # close, then a straight leg
        np.array([[1.0, 0.0, 1.0001, 0.3]]),  # an axis with almost nothing to do
    ],
)
def test_from_a_moving_state(waypoints: FloatArray) -> None:
    traj = plan_trajectory_from(MOVING, waypoints, LIMITS)
    start = traj.sample(0.0)
    # Continuous with the state it starts from.
    assert start.position == pytest.approx(MOVING.position, abs=1e-9)
    assert start.velocity == pytest.approx(MOVING.velocity, abs=1e-9)
    assert start.acceleration == pytest.approx(MOVING.acceleration, abs=1e-9)
    assert start.yaw_rate == pytest.approx(MOVING.yaw_rate, abs=1e-9)
    s = sample_densely(traj, dt=0.005)
    assert np.linalg.norm(s.velocity, axis=1).max() <= LIMITS.v_max * (1 + 1e-6)
    assert np.abs(s.yaw_rate).max() <= LIMITS.yaw_rate_max * (1 + 1e-6)
    # At rest at every waypoint; no leg takes minutes.
    for t_end, wp in zip(traj.leg_end_times, waypoints, strict=True):
        end = traj.sample(float(t_end))
        assert end.position == pytest.approx(wp[:3], abs=1e-9)
        assert np.linalg.norm(end.velocity) < 1e-9
        assert wrap_angle(end.yaw) == pytest.approx(wrap_angle(wp[3]), abs=1e-9)
    assert traj.duration < 12.0
    # Legs after the first are straight and rest to rest, as from rest.
    if len(waypoints) > 1:
        rest = plan_trajectory(waypoints[0], waypoints[1:], LIMITS)
        assert traj.leg_end_times[1] - traj.leg_end_times[0] == pytest.approx(rest.duration)


def test_positions_sample_the_flown_curve() -> None:
    traj = plan_trajectory_from(MOVING, np.array([[-2.0, 1.0, 1.2, 2.5]]), LIMITS)
    points = traj.positions(traj.duration, 0.01)
    assert points[0] == pytest.approx(MOVING.position)
    assert points[-1] == pytest.approx([-2.0, 1.0, 1.2])
    assert np.linalg.norm(np.diff(points, axis=0), axis=1).max() <= LIMITS.v_max * 0.01 + 1e-9
    # The vehicle first goes on forward: the curve is not the straight segment.
    assert points[:, 0].max() > 0.2


def test_from_a_non_finite_state_raises() -> None:
    bad = TrajectorySample(np.array([0.0, np.nan, 1.0]), np.zeros(3), np.zeros(3), 0.0, 0.0)
    with pytest.raises(TrajectoryError):
        plan_trajectory_from(bad, WAYPOINTS[:1], LIMITS)


# -- safety stops -------------------------------------------------------------------------------


def test_a_stop_mid_leg_brakes_on_the_leg_within_the_limits(traj: Trajectory) -> None:
    t = 0.5 * float(traj.leg_end_times[0])  # mid first leg, at speed
    state = traj.sample(t)
    assert np.linalg.norm(state.velocity) > 0.5
    stop = stop_trajectory(state, LIMITS)
    assert stop.curved_first_leg and stop.leg_count == 1
    s = sample_densely(stop, dt=0.005)
    assert s.position[0] == pytest.approx(state.position, abs=1e-9)
    assert s.velocity[0] == pytest.approx(state.velocity, abs=1e-9)
    end = stop.sample(stop.duration)
    assert np.linalg.norm(end.velocity) < 1e-9 and abs(end.yaw_rate) < 1e-9
    assert stop.waypoints[0, :3] == pytest.approx(end.position)
    assert np.linalg.norm(s.velocity, axis=1).max() <= LIMITS.v_max * (1 + 1e-6)
    assert np.linalg.norm(s.acceleration, axis=1).max() <= LIMITS.a_max * (1 + 1e-6)
    # The vehicle brakes along the straight leg it was on, forward only.
    direction = WAYPOINTS[0, :3] - START[:3]
    direction /= np.linalg.norm(direction)
    offsets = s.position - state.position
    along = offsets @ direction
    assert np.linalg.norm(offsets - along[:, None] * direction, axis=1).max() < 1e-6
    assert np.all(np.diff(along) >= -1e-9)
    # No longer than from the speed limit: v²/2a plus the jerk-limited ramp, under a metre.
    assert 0.0 < along[-1] < 1.0
    assert stop.duration < 1.5


def test_a_stop_from_a_curving_state_ends_at_rest() -> None:
    stop = stop_trajectory(MOVING, LIMITS)
    end = stop.sample(stop.duration)
    assert np.linalg.norm(end.velocity) < 1e-9
    assert np.linalg.norm(end.acceleration) < 1e-9
    s = sample_densely(stop, dt=0.005)
    assert np.linalg.norm(s.velocity, axis=1).max() <= LIMITS.v_max * (1 + 1e-6)
    assert stop.duration < 2.0


def test_positions_can_start_part_way() -> None:
    traj = plan_trajectory_from(MOVING, np.array([[-2.0, 1.0, 1.2, 2.5]]), LIMITS)
    points = traj.positions(traj.duration, 0.01, start=1.0)
    assert points[0] == pytest.approx(traj.sample(1.0).position)
    assert points[-1] == pytest.approx([-2.0, 1.0, 1.2])
