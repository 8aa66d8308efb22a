"""Database tables (SQLAlchemy 2). Alembic revisions in `migrations/` mirror them exactly.

Times are UTC. Series are stored compactly: little-endian float32 arrays in binary columns.
"""

from __future__ import annotations

import enum
from datetime import UTC, datetime
from typing import Any

from sqlalchemy import (
    JSON,
    BigInteger,
    Boolean,
    DateTime,
    Float,
    ForeignKey,
    Index,
    Integer,
    LargeBinary,
    String,
    Text,
    UniqueConstraint,
    text,
)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column, relationship
from sqlalchemy.types import TypeDecorator


def utcnow() -> datetime:
    return datetime.now(UTC)


class Base(DeclarativeBase):
    pass


class RunState(enum.StrEnum):
    """States of a run; the last three are final and never change."""

    QUEUED = "queued"
    RUNNING = "running"
    SUCCEEDED = "succeeded"
    FAILED = "failed"
    CANCELLED = "cancelled"

    @property
    def final(self) -> bool:
        return self in (RunState.SUCCEEDED, RunState.FAILED, RunState.CANCELLED)


FINAL_STATES = tuple(s.value for s in RunState if s.final)
# The benchmark version of results stored before runs named theirs (migration 0003), and of a
# run whose worker could not tell its own.
LEGACY_VERSION = "legacy"
UNKNOWN_VERSION = "unknown"
ACTIVE_STATES = (RunState.QUEUED.value, RunState.RUNNING.value)


class FailureKind(enum.StrEnum):
    """Who a failure is blamed on: platform failures do not count against quotas."""

    PLANNER = "planner"
    PLATFORM = "platform"


class UtcDateTime(TypeDecorator[datetime]):
    """Timezone-aware UTC on every backend: SQLite hands back naive values, read here as UTC."""

    impl = DateTime(timezone=True)
    cache_ok = True

    def process_bind_param(self, value: datetime | None, dialect: Any) -> datetime | None:
        if value is not None and value.tzinfo is None:
            value = value.replace(tzinfo=UTC)
        return value

    def process_result_value(self, value: datetime | None, dialect: Any) -> datetime | None:
        if value is not None and value.tzinfo is None:
            value = value.replace(tzinfo=UTC)
        return value


_TS = UtcDateTime()


class User(Base):
    __tablename__ = "users"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(64), unique=True)
    is_admin: Mapped[bool] = mapped_column(Boolean, default=False)
    created_at: Mapped[datetime] = mapped_column(_TS, default=utcnow)

    tokens: Mapped[list[ApiToken]] = relationship(back_populates="user")


class ApiToken(Base):
    """A bearer token, stored only as its keyed hash; `prefix` identifies it in listings."""

    __tablename__ = "api_tokens"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    user_id: Mapped[int] = mapped_column(ForeignKey("users.id", ondelete="CASCADE"), index=True)
    token_hash: Mapped[str] = mapped_column(String(64), unique=True)
    prefix: Mapped[str] = mapped_column(String(16))
    created_at: Mapped[datetime] = mapped_column(_TS, default=utcnow)
    last_used_at: Mapped[datetime | None] = mapped_column(_TS, nullable=True)
    revoked: Mapped[bool] = mapped_column(Boolean, default=False)

    user: Mapped[User] = relationship(back_populates="tokens")


PUBLIC_SPLIT = "public"
HELDOUT_SPLIT = "heldout"


class AreaRow(Base):
    __tablename__ = "areas"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(40), unique=True)
    builtin: Mapped[bool] = mapped_column(Boolean, default=True)
    owner_id: Mapped[int | None] = mapped_column(ForeignKey("users.id"), nullable=True)
    content_hash: Mapped[str] = mapped_column(String(64))
    plateau_s: Mapped[float] = mapped_column(Float)
    voxel_size: Mapped[float] = mapped_column(Float)
    stats: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    created_at: Mapped[datetime] = mapped_column(_TS, default=utcnow)
    # "public", or "heldout": generated from a secret seed (`server.heldout`), its scene shown
    # to admins only, ranked on a board of its own and only with areas of its generation.
    split: Mapped[str] = mapped_column(String(16), default=PUBLIC_SPLIT,
                                       server_default=text("'public'"), index=True)
    heldout_generation: Mapped[int | None] = mapped_column(Integer, nullable=True)

    @property
    def heldout(self) -> bool:
        return self.split == HELDOUT_SPLIT


class HeldoutGeneration(Base):
    """A generation of the held-out seeds: rotating them (`flybo heldout rotate`) starts a new
    one; results on areas of an older one stay, filed under theirs."""

    __tablename__ = "heldout_generations"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)  # the generation number
    note: Mapped[str] = mapped_column(Text, default="")
    created_at: Mapped[datetime] = mapped_column(_TS, default=utcnow)


class PlannerRow(Base):
    __tablename__ = "planners"
    __table_args__ = (UniqueConstraint("name", "version", name="uq_planners_name_version"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(64))
    version: Mapped[int] = mapped_column(Integer)
    builtin: Mapped[bool] = mapped_column(Boolean, default=True)
    owner_id: Mapped[int | None] = mapped_column(ForeignKey("users.id"), nullable=True)
    description: Mapped[str] = mapped_column(Text, default="")
    reference: Mapped[str] = mapped_column(Text, default="")
    # `planners.fidelity`: "original", "variant" or "" (not stated, as uploaded planners).
    method: Mapped[str] = mapped_column(String(16), default="", server_default=text("''"))
    code_hash: Mapped[str] = mapped_column(String(64), default="")
    config: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    created_at: Mapped[datetime] = mapped_column(_TS, default=utcnow)

    @property
    def key(self) -> str:
        return f"{self.name}-v{self.version}"


class JobGroup(Base):
    """Jobs submitted together (`flybo benchmark`): one per planner of a suite."""

    __tablename__ = "job_groups"
    __table_args__ = (
        UniqueConstraint("user_id", "idempotency_key", name="uq_job_groups_user_idempotency_key"),
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    user_id: Mapped[int] = mapped_column(ForeignKey("users.id"), index=True)
    name: Mapped[str] = mapped_column(String(128))
    preset: Mapped[str] = mapped_column(String(32))
    runs_per_area: Mapped[int] = mapped_column(Integer)
    seconds: Mapped[float | None] = mapped_column(Float, nullable=True)
    # A fraction of each area's plateau time; None: the whole plateau (or `seconds`).
    time_scale: Mapped[float | None] = mapped_column(Float, nullable=True)
    idempotency_key: Mapped[str | None] = mapped_column(String(128), nullable=True)
    request_hash: Mapped[str] = mapped_column(String(64))
    created_at: Mapped[datetime] = mapped_column(_TS, default=utcnow, index=True)

    user: Mapped[User] = relationship()
    jobs: Mapped[list[Job]] = relationship(back_populates="group", order_by="Job.id")


class Job(Base):
    __tablename__ = "jobs"
    __table_args__ = (
        UniqueConstraint("user_id", "idempotency_key", name="uq_jobs_user_idempotency_key"),
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    user_id: Mapped[int] = mapped_column(ForeignKey("users.id"), index=True)
    planner_id: Mapped[int] = mapped_column(ForeignKey("planners.id"), index=True)
    preset: Mapped[str] = mapped_column(String(32))
    seconds: Mapped[float | None] = mapped_column(Float, nullable=True)
    runs_per_area: Mapped[int] = mapped_column(Integer)
    idempotency_key: Mapped[str | None] = mapped_column(String(128), nullable=True)
    request_hash: Mapped[str] = mapped_column(String(64))
    rerun_of_id: Mapped[int | None] = mapped_column(ForeignKey("jobs.id"), nullable=True)
    created_at: Mapped[datetime] = mapped_column(_TS, default=utcnow, index=True)
    group_id: Mapped[int | None] = mapped_column(ForeignKey("job_groups.id"), nullable=True,
                                                 index=True)
    # Loaded from a baseline dataset (`server.baselines`), not flown by this service.
    reference: Mapped[bool] = mapped_column(Boolean, default=False,
                                            server_default=text("false"))

    planner: Mapped[PlannerRow] = relationship()
    user: Mapped[User] = relationship()
    group: Mapped[JobGroup | None] = relationship(back_populates="jobs")
    runs: Mapped[list[Run]] = relationship(back_populates="job", order_by="Run.id")


class Run(Base):
    __tablename__ = "runs"
    __table_args__ = (Index("ix_runs_status_heartbeat", "status", "heartbeat_at"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    job_id: Mapped[int] = mapped_column(ForeignKey("jobs.id"), index=True)
    area_id: Mapped[int] = mapped_column(ForeignKey("areas.id"), index=True)
    seed: Mapped[int] = mapped_column(Integer)
    preset: Mapped[str] = mapped_column(String(32))
    seconds: Mapped[float] = mapped_column(Float)
    status: Mapped[str] = mapped_column(String(16), default=RunState.QUEUED.value, index=True)
    attempts: Mapped[int] = mapped_column(Integer, default=0)
    # A fresh token per claim: only the attempt holding it may finish the run.
    claim_token: Mapped[str | None] = mapped_column(String(32), nullable=True)
    worker: Mapped[str | None] = mapped_column(String(128), nullable=True)
    progress: Mapped[float] = mapped_column(Float, default=0.0)
    sim_time_s: Mapped[float] = mapped_column(Float, default=0.0)
    cancel_requested: Mapped[bool] = mapped_column(Boolean, default=False)
    enqueued_at: Mapped[datetime | None] = mapped_column(_TS, nullable=True)
    started_at: Mapped[datetime | None] = mapped_column(_TS, nullable=True)
    heartbeat_at: Mapped[datetime | None] = mapped_column(_TS, nullable=True)
    finished_at: Mapped[datetime | None] = mapped_column(_TS, nullable=True)
    wall_time_s: Mapped[float | None] = mapped_column(Float, nullable=True)
    error: Mapped[str | None] = mapped_column(Text, nullable=True)
    log_tail: Mapped[str] = mapped_column(Text, default="")  # the last lines, live while running
    failure_kind: Mapped[str | None] = mapped_column(String(16), nullable=True)

    job: Mapped[Job] = relationship(back_populates="runs")
    area: Mapped[AreaRow] = relationship()
    result: Mapped[RunResult | None] = relationship(back_populates="run", uselist=False)
    series: Mapped[MetricSeries | None] = relationship(uselist=False)
    artifacts: Mapped[list[Artifact]] = relationship(order_by="Artifact.kind")


class MetricSeries(Base):
    """The run's curves as float32 arrays: explored volume each second, recall snapshots."""

    __tablename__ = "metric_series"

    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id", ondelete="CASCADE"),
                                        primary_key=True)
    time_s: Mapped[bytes] = mapped_column(LargeBinary)
    explored_volume_m3: Mapped[bytes] = mapped_column(LargeBinary)
    recall_time_s: Mapped[bytes] = mapped_column(LargeBinary)
    surface_recall: Mapped[bytes] = mapped_column(LargeBinary)


class RunResult(Base):
    """Final metrics of a run (see `docs/metrics.md`)."""

    __tablename__ = "run_results"

    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id", ondelete="CASCADE"),
                                        primary_key=True)
    outcome: Mapped[str] = mapped_column(String(16))  # the episode's: succeeded, crashed, failed
    reason: Mapped[str] = mapped_column(Text)
    simulated_until_s: Mapped[float] = mapped_column(Float)
    explored_volume_m3: Mapped[float] = mapped_column(Float)
    volume_at_plateau_m3: Mapped[float] = mapped_column(Float)
    observable_volume_m3: Mapped[float] = mapped_column(Float)
    coverage: Mapped[float] = mapped_column(Float)
    volumetric_efficiency: Mapped[float] = mapped_column(Float)
    precision: Mapped[float | None] = mapped_column(Float, nullable=True)
    recall: Mapped[float | None] = mapped_column(Float, nullable=True)
    fscore: Mapped[float | None] = mapped_column(Float, nullable=True)
    rmse_m: Mapped[float | None] = mapped_column(Float, nullable=True)
    collisions: Mapped[int] = mapped_column(Integer)
    path_length_m: Mapped[float] = mapped_column(Float)
    iterations: Mapped[int] = mapped_column(Integer)
    planning_ms_median: Mapped[float | None] = mapped_column(Float, nullable=True)
    planning_ms_mean: Mapped[float | None] = mapped_column(Float, nullable=True)
    planning_ms_max: Mapped[float | None] = mapped_column(Float, nullable=True)
    wall_seconds: Mapped[float] = mapped_column(Float)
    # What made the result: the benchmark version (`flybo.versions`; leaderboards never rank
    # results of different versions together) and the whole reproducibility record
    # (`flybo/record.py`). Results stored before they were recorded read `LEGACY_VERSION`.
    benchmark_version: Mapped[str] = mapped_column(String(64), index=True)
    record: Mapped[dict[str, Any] | None] = mapped_column(JSON, nullable=True)
    # Every number the measures reported (`result.json`'s `metrics`, keyed as
    # `sim.measures.metric_infos()`); None for legacy results.
    metrics: Mapped[dict[str, Any] | None] = mapped_column(JSON, nullable=True)

    run: Mapped[Run] = relationship(back_populates="result")


class Artifact(Base):
    __tablename__ = "artifacts"
    __table_args__ = (UniqueConstraint("run_id", "kind", name="uq_artifacts_run_kind"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id", ondelete="CASCADE"), index=True)
    kind: Mapped[str] = mapped_column(String(32))
    location: Mapped[str] = mapped_column(Text)
    size_bytes: Mapped[int] = mapped_column(BigInteger)
    sha256: Mapped[str] = mapped_column(String(64))
    content_type: Mapped[str] = mapped_column(String(64))
    created_at: Mapped[datetime] = mapped_column(_TS, default=utcnow)
