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
    split: str = Field(default="public", description="'public', or 'heldout' (seen by admins "
                       "only)")
    heldout_generation: int | None = None


class PlannerOut(BaseModel):
    name: str
    version: int
    id: str = Field(description="name-vVERSION, as in results")
    builtin: bool
    description: str
    reference: str
    method: str = Field(default="", description="'original': the method as its paper "
                        "published it (the rows to set beside the paper's); 'variant': it "
                        "differs from it; '': not stated (uploaded planners)")
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
    reference: bool = Field(default=False, description="its runs are reference results "
                            "loaded from a baseline dataset (`docs/baselines.md`), not flown "
                            "by this service")
    runs: list[RunBrief]


class ResultOut(BaseModel):
    benchmark_version: str = Field(description="the benchmark version the run was made with "
                                   "('legacy': stored before runs named theirs)")
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
    metrics: dict[str, float | int | None] | None = Field(
        default=None, description="every number the measures reported, by key "
        "(`result.json`'s `metrics`); null for legacy results")
    record: dict[str, Any] | None = Field(
        default=None, description="the reproducibility record (`result.json`'s "
        "`reproducibility`): benchmark version, code, preset, area, planner, seed, libraries, "
        "machine, and what could not be recorded (`missing`); null for legacy results")


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
    split: str = Field(default="public", description="the area's split: 'public' or 'heldout' "
                       "(then its files, log and record are shown to admins only)")
    heldout_generation: int | None = Field(default=None, description="the held-out area's "
                                           "generation; results of different ones are never "
                                           "ranked together")


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
    ci_low: float | None = Field(default=None, description="the 95 % confidence interval of "
                                 "the mean over runs (percentile bootstrap, "
                                 "`Leaderboard.statistics`): lower bound")
    ci_high: float | None = Field(default=None, description="its upper bound")


class Interval(BaseModel):
    """A 95 % confidence interval (`Leaderboard.statistics`)."""

    low: float
    high: float


class StatisticsInfo(BaseModel):
    """How the leaderboard's intervals and tie groups are made (`docs/statistics.md`)."""

    method: str
    confidence: float
    resamples: int
    seed: int
    tie_rule: str


class MetricOut(BaseModel):
    """A metric the leaderboard shows besides its fixed columns (`sim.measures`)."""

    key: str
    label: str
    unit: str
    higher_is_better: bool
    fmt: str = Field(description="a Python format spec for the value")


class LeaderboardEntry(BaseModel):
    planner: str
    builtin: bool
    method: str = Field(default="", description="'original': the method as its paper "
                        "published it (the rows to set beside the paper's); 'variant': it "
                        "differs from it; '': not stated (uploaded planners)")
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
    coverage_group_rank: int | None = Field(
        default=None, description="the rank of its tie group on this area by mean coverage: "
        "planners whose coverage intervals cannot be told apart share it")
    fscore_group_rank: int | None = Field(
        default=None, description="the same by mean F-score; null without F-scores")
    metrics: dict[str, Spread] = Field(
        default_factory=dict, description="each of `Leaderboard.metrics` over the runs "
        "(a run where it is undefined, such as a coverage never reached, is left out)")


class LeaderboardPlanner(BaseModel):
    planner: str
    builtin: bool
    method: str = Field(default="", description="'original': the method as its paper "
                        "published it (the rows to set beside the paper's); 'variant': it "
                        "differs from it; '': not stated (uploaded planners)")
    areas: int
    mean_coverage: float
    mean_relative_coverage: float
    mean_fscore: float | None
    mean_coverage_rank: float
    mean_fscore_rank: float | None
    rank: int = Field(description="by mean coverage rank; planners whose mean coverage rank "
                      "intervals cannot be told apart share a rank (tie groups, "
                      "`Leaderboard.statistics`)")
    mean_rmse_m: float | None = Field(default=None, description="mean over areas of the "
                                      "per-area mean RMSE")
    pareto: bool = Field(default=False, description="not dominated in (mean coverage rank, "
                         "mean F-score rank): no planner is at least as good in both and "
                         "better in one")
    mean_metrics: dict[str, float | None] = Field(
        default_factory=dict, description="each of `Leaderboard.metrics`: the mean over areas "
        "of the per-area means (areas where it is undefined left out)")
    mean_coverage_ci: Interval | None = None
    public_mean_coverage: float | None = Field(
        default=None, description="on the held-out board: the planner's mean coverage on the "
        "public board of the same preset and benchmark version (None without public results)")
    public_gap: float | None = Field(
        default=None, description="on the held-out board: public minus held-out mean coverage; "
        "a large positive gap hints at tuning to the public areas")
    mean_relative_coverage_ci: Interval | None = None
    mean_fscore_ci: Interval | None = None
    mean_coverage_rank_ci: Interval | None = None
    mean_fscore_rank_ci: Interval | None = None


class Leaderboard(BaseModel):
    preset: str
    split: str = Field(default="public", description="'public': the public areas; 'heldout': "
                       "the held-out areas of one generation")
    heldout_generation: int | None = Field(default=None, description="the generation ranked, "
                                           "on the held-out board")
    benchmark_version: str = Field(description="the one benchmark version whose results "
                                   "are ranked")
    metrics: list[MetricOut] = Field(default_factory=list,
                                     description="the leaderboard metrics of `sim.measures`")
    areas: list[str]
    overall: list[LeaderboardPlanner]
    entries: list[LeaderboardEntry]
    statistics: StatisticsInfo | None = Field(default=None, description="how the intervals "
                                              "and tie groups were made")


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
    benchmark_version: str
    area: str
    plateau_s: float | None
    planners: list[PlannerCurves]


class BenchmarkVersionOut(BaseModel):
    benchmark_version: str
    runs: int = Field(description="succeeded runs with results")
    current: bool = Field(description="the version of this service's code")


class BenchmarkVersions(BaseModel):
    current: str = Field(description="the version of this service's code: the leaderboard's "
                         "default")
    preset: str | None = Field(description="the preset the counts are of; null: all presets")
    versions: list[BenchmarkVersionOut] = Field(
        description="the versions with results, the newest result's first")
