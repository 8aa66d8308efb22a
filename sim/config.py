"""Episode configuration and the named presets.

A preset fixes everything that shapes a run except the area, the planner and the seed. What is
integrated when is part of the preset: the camera always runs at its rate (20 Hz), and a preset
chooses which frames are fused into the occupancy map and the TSDF (see `docs/presets.md`).
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from sim.camera import CameraConfig
from sim.noise import DepthNoiseConfig, OdometryNoiseConfig
from sim.occupancy import OccupancyConfig
from sim.tsdf import TsdfConfig
from sim.vehicle import VehicleLimits
from sim.world import PhysicsConfig


class EpisodeConfig(BaseModel):
    """Everything about a run but the area, the planner and the seed."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    camera: CameraConfig = CameraConfig()
    depth_noise: DepthNoiseConfig = DepthNoiseConfig()
    odometry_noise: OdometryNoiseConfig = OdometryNoiseConfig()
    occupancy: OccupancyConfig = OccupancyConfig()
    tsdf: TsdfConfig = TsdfConfig()
    physics: PhysicsConfig = PhysicsConfig()
    limits: VehicleLimits = VehicleLimits()
    occupancy_every_n_frames: int = Field(1, ge=1, description="fuse every n-th camera frame")
    occupancy_pixel_stride: int = Field(1, ge=1, description="cast every n-th row and column")
    tsdf_every_n_frames: int = Field(4, ge=1)
    startup_spin: bool = Field(True, description="turn once in place before the first plan")
    start_free_radius_m: float = Field(
        1.0, ge=0.0, description="known free sphere around the start (never into a surface)"
    )
    safety_margin_m: float = Field(
        0.15, ge=0.0, description="added to the vehicle radius for traversability"
    )
    safety_stops: bool = Field(
        True,
        description="brake to a stop when an occupancy update finds an obstacle the vehicle "
        "could touch on the rest of the path being flown",
    )
    planning_time_charge: Literal["cpu", "wall", "none"] = Field(
        "cpu",
        description="what a plan call costs on the simulated clock: 'cpu' the CPU time the "
        "planner used (all its threads, read by the runner) in reference seconds "
        "(`sim.reference_speed`), 'wall' its wall time (moves with machine load), 'none' "
        "nothing (bit-for-bit repeatable)",
    )
    surface_tau_m: float = Field(0.05, gt=0.0, description="distance threshold of surface metrics")
    recall_interval_s: float = Field(20.0, gt=0.0)
    recall_sample_points: int = Field(
        20_000, ge=1000, description="ground-truth points in recall snapshots (final: all)"
    )
    final_recall_points: int = Field(
        500_000, ge=1000,
        description="ground-truth points the final recall is computed over (all when fewer)",
    )
    surface_snapshot_interval_s: float = Field(
        150.0, gt=0.0, description="reconstructed surface kept in the recording"
    )
    surface_snapshot_voxel_m: float = Field(0.1, gt=0.0, description="thinning of snapshots")
    volume_interval_s: float = Field(1.0, gt=0.0)
    keyframe_interval_s: float = Field(2.0, gt=0.0)
    pose_record_hz: float = Field(10.0, gt=0.0)
    max_failed_plans: int = Field(20, ge=1, description="consecutive unusable plans before failing")
    failed_plan_hover_s: float = Field(0.5, ge=0.0)

    @property
    def safety_radius_m(self) -> float:
        return self.limits.radius_m + self.safety_margin_m


def _preset(**overrides: object) -> EpisodeConfig:
    return EpisodeConfig.model_validate(overrides)


PRESETS: dict[str, EpisodeConfig] = {
    # The benchmark's default: the camera runs at 20 Hz, 160 x 120. Every fourth frame (5 Hz) is
    # fused into the occupancy map with every other row and column (80 x 60 rays), and every
    # eighth (2.5 Hz) at full resolution into a 5 cm TSDF. `docs/presets.md` shows what this
    # costs against `full` on the same flight.
    "default": _preset(occupancy_every_n_frames=4, occupancy_pixel_stride=2, tsdf_every_n_frames=8),
    # Every frame into both maps at full resolution: the reference the default is checked against.
    "full": _preset(occupancy_every_n_frames=1, tsdf_every_n_frames=1),
    # No sensor or odometry noise, repeatable: for tests and for comparing planners exactly.
    "exact": _preset(
        occupancy_every_n_frames=4,
        occupancy_pixel_stride=2,
        tsdf_every_n_frames=8,
        depth_noise=DepthNoiseConfig(enabled=False),
        odometry_noise=OdometryNoiseConfig(enabled=False),
        planning_time_charge="none",
    ),
}


class UnknownPresetError(ValueError):
    """No preset has the requested name."""


def preset(name: str) -> EpisodeConfig:
    """The preset called `name`."""
    try:
        return PRESETS[name]
    except KeyError:
        raise UnknownPresetError(
            f"unknown preset {name!r}; known presets: {', '.join(sorted(PRESETS))}"
        ) from None
