"""Request and response bodies of the REST API."""

from __future__ import annotations

from datetime import datetime
from typing import Any, Generic, TypeVar

from pydantic import BaseModel, ConfigDict, Field, field_validator

T = TypeVar("T")

NAME_PATTERN = r"^[a-z0-9][a-z0-9-]{0,63}$"


class ErrorBody(BaseModel):
    detail: str = Field(description="what was wrong, in one sentence")


class Page(BaseModel, Generic[T]):
    items: list[T]
    total: int
    limit: int
    offset: int


class AreaOut(BaseModel):
    name: str
    builtin: bool
    title: str
    content_hash: str
    plateau_s: float
    voxel_size: float
    stats: dict[str, Any]


class PlannerOut(BaseModel):
    name: str
    version: int
    id: str = Field(description="name-vVERSION, as in results")
    builtin: bool
    description: str
    reference: str
    config: dict[str, Any]
    owner: str | None
    code_hash: str | None = None


class JobCreate(BaseModel):
    model_config = ConfigDict(extra="forbid")

    planner: str = Field(description="planner name, or name-vN for one version",
                         min_length=1, max_length=80)
    areas: list[str] = Field(min_length=1, max_length=64)
    runs: int = Field(default=1, ge=1, le=100, description="runs (seeds 0..runs-1) per area")
    seconds: float | None = Field(default=None, gt=0, allow_inf_nan=False,
                                  description="simulated seconds; the plateau time if omitted")
    preset: str = Field(default="default", min_length=1, max_length=32)

    @field_validator("areas")
    @classmethod
    def _unique_areas(cls, value: list[str]) -> list[str]:
        if len(set(value)) != len(value):
            raise ValueError("areas must not repeat")
        return value


class RunBrief(BaseModel):
    id: int
    area: str
    seed: int
    status: str
    progress: float


class JobOut(BaseModel):
    id: int
    status: str
    progress: float
    planner: str
    preset: str
    seconds: float | None
    runs_per_area: int
    areas: list[str]
    owner: str
    created_at: datetime
    rerun_of: int | None
    group_id: int | None = Field(description="the job group (`/groups/{id}`) it belongs to, "
                                 "if any; a re-run joins the group of the job it re-runs")
    runs: list[RunBrief]


class ResultOut(BaseModel):
    outcome: str
    reason: str
    simulated_until_s: float
    explored_volume_m3: float
    volume_at_plateau_m3: float
    observable_volume_m3: float
    coverage: float
    volumetric_efficiency: float
    precision: float | None
    recall: float | None
    fscore: float | None
    rmse_m: float | None
    collisions: int
    path_length_m: float
    iterations: int
    planning_ms_median: float | None
    planning_ms_mean: float | None
    planning_ms_max: float | None
    wall_seconds: float


class ArtifactOut(BaseModel):
    kind: str
    size_bytes: int
    sha256: str
    content_type: str
    url: str


class RunOut(BaseModel):
    id: int
    job_id: int
    planner: str
    area: str
    seed: int
    preset: str
    seconds: float
    status: str
    progress: float
    sim_time_s: float
    attempts: int
    worker: str | None
    started_at: datetime | None
    finished_at: datetime | None
    wall_time_s: float | None
    error: str | None
    failure_kind: str | None
    result: ResultOut | None
    artifacts: list[ArtifactOut]


class SeriesOut(BaseModel):
    run_id: int
    time_s: list[float]
    explored_volume_m3: list[float]
    recall_time_s: list[float]
    surface_recall: list[float]


class Spread(BaseModel):
    mean: float | None
    min: float | None
    max: float | None


class LeaderboardEntry(BaseModel):
    planner: str
    builtin: bool
    area: str
    runs: int
    coverage: Spread
    relative_coverage: Spread
    fscore: Spread
    rmse_m: Spread
    path_length_m: Spread
    iterations: Spread
    planning_ms: Spread
    collisions: int
    coverage_rank: float
    fscore_rank: float | None


class LeaderboardPlanner(BaseModel):
    planner: str
    builtin: bool
    areas: int
    mean_coverage: float
    mean_relative_coverage: float
    mean_fscore: float | None
    mean_coverage_rank: float
    mean_fscore_rank: float | None
    rank: int
    mean_rmse_m: float | None = Field(default=None, description="mean over areas of the "
                                      "per-area mean RMSE")
    pareto: bool = Field(default=False, description="not dominated in (mean coverage rank, "
                         "mean F-score rank): no planner is at least as good in both and "
                         "better in one")


class Leaderboard(BaseModel):
    preset: str
    areas: list[str]
    overall: list[LeaderboardPlanner]
    entries: list[LeaderboardEntry]


class Band(BaseModel):
    """A curve over runs: at each time, the mean, min and max of the runs that reached it."""

    mean: list[float | None]
    min: list[float | None]
    max: list[float | None]


class PlannerCurves(BaseModel):
    planner: str
    builtin: bool
    runs: int
    time_s: list[float]
    explored_volume_m3: Band
    recall_time_s: list[float]
    surface_recall: Band


class Curves(BaseModel):
    preset: str
    area: str
    plateau_s: float | None
    planners: list[PlannerCurves]
