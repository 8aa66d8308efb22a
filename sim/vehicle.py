"""Vehicle limits shared by the trajectory generator, the physics body and the planners."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field


class VehicleLimits(BaseModel):
    """The MAV: a rigid sphere with motion limits (defaults are the benchmark's vehicle)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    radius_m: float = Field(0.3, gt=0.0)
    mass_kg: float = Field(0.68, gt=0.0)
    v_max: float = Field(1.5, gt=0.0, description="m/s, norm of the velocity")
    a_max: float = Field(2.5, gt=0.0, description="m/s², norm of the acceleration")
    j_max: float = Field(10.0, gt=0.0, description="m/s³, norm of the jerk")
    yaw_rate_max: float = Field(1.0, gt=0.0, description="rad/s")
    yaw_acc_max: float = Field(2.0, gt=0.0, description="rad/s²")
    yaw_jerk_max: float = Field(10.0, gt=0.0, description="rad/s³")
