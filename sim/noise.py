"""Sensor and odometry noise, seeded and switchable off.

Depth noise follows the axial noise model of Nguyen, Izadi and Lovell (3DIMPVT 2012) for
structured-light depth cameras: sigma(z) = a + b * (z - z0)^2, Gaussian, applied to z-depth.
Odometry noise is a bounded random walk on position and yaw: the pose the mapping and the planner
see drifts from the true pose but never by more than the bound on any axis (so at most
sqrt(3) times the bound in position).
"""

from __future__ import annotations

import math

import numba
import numpy as np
import numpy.typing as npt
from pydantic import BaseModel, ConfigDict, Field

from sim.geometry import Pose, wrap_angle


class DepthNoiseConfig(BaseModel):
    """sigma(z) = sigma_a + sigma_b * (z - z0)^2 metres; disabled gives exact depth."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    enabled: bool = True
    sigma_a: float = Field(0.0012, ge=0.0)
    sigma_b: float = Field(0.0019, ge=0.0)
    z0: float = 0.4


class OdometryNoiseConfig(BaseModel):
    """Per-frame random-walk steps and their bounds."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    enabled: bool = True
    position_step_m: float = Field(0.002, ge=0.0)
    position_bound_m: float = Field(0.05, ge=0.0)
    yaw_step_rad: float = Field(0.001, ge=0.0)
    yaw_bound_rad: float = Field(0.02, ge=0.0)


def depth_sigma(z: npt.NDArray[np.floating], config: DepthNoiseConfig) -> npt.NDArray[np.float64]:
    """Standard deviation of the depth error at z-depth `z` (same shape as z)."""
    return config.sigma_a + config.sigma_b * (np.asarray(z, dtype=np.float64) - config.z0) ** 2


def add_depth_noise(
    depth: npt.NDArray[np.float32], config: DepthNoiseConfig, rng: np.random.Generator
) -> npt.NDArray[np.float32]:
    """A noisy copy of `depth`; NaN (no return) stays NaN. Draws from `rng` even when disabled
    or all NaN, so the random stream does not depend on the scene or the switch."""
    noise = rng.standard_normal(depth.shape)
    if not config.enabled:
        return depth.copy()
    flat = np.ascontiguousarray(depth, dtype=np.float32).reshape(-1)
    noisy: npt.NDArray[np.float32] = _noisy(flat, noise.reshape(-1), config.sigma_a,
                                            config.sigma_b, config.z0).reshape(depth.shape)
    return noisy


@numba.njit(cache=True)
def _noisy(depth: npt.NDArray[np.float32], noise: npt.NDArray[np.float64], a: float, b: float,
           z0: float) -> npt.NDArray[np.float32]:  # pragma: no cover - numba
    """(N,) float32 depth + float32(noise * sigma(depth)), floored at 0 where finite: in one
    pass the operations NumPy's form made array by array (`depth_sigma` in float64, the
    product rounded to float32, a float32 sum), so the result is the same to the bit."""
    out = np.empty(depth.shape[0], np.float32)
    zero = np.float32(0.0)
    for i in range(depth.shape[0]):
        d = depth[i]
        dz = np.float64(d) - z0
        v = d + np.float32(noise[i] * (a + b * (dz * dz)))
        if math.isfinite(v) and not v >= zero:
            v = zero
        out[i] = v
    return out


class OdometryDrift:
    """Bounded random walk of the estimated pose around the true pose."""

    def __init__(self, config: OdometryNoiseConfig, rng: np.random.Generator) -> None:
        self.config = config
        self._rng = rng
        self.offset = np.zeros(3)
        self.yaw_offset = 0.0

    def step(self) -> None:
        """Advance the walk by one camera frame."""
        cfg = self.config
        draw = self._rng.standard_normal(4)
        if not cfg.enabled:
            return
        bound = cfg.position_bound_m
        # Clamped as `np.clip` clamps, without its per-call cost (four times a fused frame).
        self.offset = np.minimum(np.maximum(self.offset + draw[:3] * cfg.position_step_m,
                                            -bound), bound)
        self.yaw_offset = min(max(self.yaw_offset + float(draw[3]) * cfg.yaw_step_rad,
                                  -cfg.yaw_bound_rad), cfg.yaw_bound_rad)

    def estimate(self, true_pose: Pose) -> Pose:
        """The pose odometry reports for `true_pose`."""
        return Pose(true_pose.position + self.offset, wrap_angle(true_pose.yaw + self.yaw_offset))
