"""FALCON's time lower bound between poses (the public code's
`PathCostEvaluator::computePathCost`), used for the coverage path, the frontier ordering and the
refinement (`planners.falcon`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Dynamics:
    """The limits the bound is computed with: speed and acceleration (m/s, m/s²), the vertical
    speed a height change is charged at (m/s), yaw rate and yaw acceleration (rad/s, rad/s²)."""

    v_max: float
    a_max: float
    vz_max: float
    yaw_rate: float
    yaw_acc: float


def time_cost(length_m: npt.ArrayLike, p1: npt.ArrayLike, p2: npt.ArrayLike,
              yaw1: npt.ArrayLike, yaw2: npt.ArrayLike, velocity: FloatArray,
              dyn: Dynamics) -> FloatArray:
    """max(translation time, yaw time) from (p1, yaw1) to (p2, yaw2) along `length_m`.

    Translation: length / v_max, plus the height change at `vz_max`, plus, while moving, the
    time to turn the current velocity toward the goal at `a_max` ((v_max - v_c)^2 / (2 v_max
    a_max), and 2 |v_c| / a_max more when the goal lies behind, v_c being the velocity's
    component toward it). Yaw: a rest-to-rest turn limited by yaw rate and yaw acceleration.
    Arguments broadcast (positions on a last axis of 3); returns their broadcast shape.
    """
    a = np.asarray(p1, dtype=np.float64)
    b = np.asarray(p2, dtype=np.float64)
    step = b - a
    pos = np.asarray(length_m, dtype=np.float64) / dyn.v_max + np.abs(step[..., 2]) / dyn.vz_max
    if float(np.linalg.norm(velocity)) > 1e-3:
        dist = np.linalg.norm(step, axis=-1)
        vc = np.sum(step * velocity, axis=-1) / np.maximum(dist, 1e-12)
        turn = (dyn.v_max - np.abs(vc)) ** 2 / (2.0 * dyn.v_max * dyn.a_max)
        turn = turn + np.where(vc < 0.0, 2.0 * np.abs(vc) / dyn.a_max, 0.0)
        pos = pos + np.where(dist > 1e-9, turn, 0.0)
    diff = np.abs(np.asarray(yaw2, dtype=np.float64) - np.asarray(yaw1, dtype=np.float64))
    diff = np.minimum(diff % (2.0 * np.pi), 2.0 * np.pi - diff % (2.0 * np.pi))
    ramp = 0.5 * dyn.yaw_rate ** 2 / dyn.yaw_acc  # the angle turned while reaching full rate
    yaw = np.where(diff < ramp, np.sqrt(2.0 * diff / dyn.yaw_acc),
                   dyn.yaw_rate / dyn.yaw_acc + (diff - ramp) / dyn.yaw_rate)
    out: FloatArray = np.maximum(pos, yaw)
    return out
