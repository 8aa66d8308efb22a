"""Poses and rotations shared by the simulator and the planners.

Frames (see `docs/conventions.md`): world is z-up in metres; the body frame has x forward, y left,
z up; the vehicle stays level, so a pose is a position and a yaw about +z.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Pose:
    """A level pose.

    Attributes:
        position: (3,) metres, world frame.
        yaw: radians about +z from +x, in (-pi, pi].
    """

    position: FloatArray
    yaw: float


def yaw_matrix(yaw: float) -> FloatArray:
    """(3, 3) rotation about +z taking body vectors to world vectors."""
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def wrap_angle(angle: float) -> float:
    """Angle wrapped to (-pi, pi]."""
    wrapped = (angle + np.pi) % (2.0 * np.pi) - np.pi
    return float(np.pi if wrapped == -np.pi else wrapped)
