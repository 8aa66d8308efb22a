"""The service's settings: one pydantic-settings class, read from `FLYBO_*` environment variables.

Every folder the CLI, the API and the workers use comes from here. Two roots:

- `data_dir` (`FLYBO_DATA_DIR`, default `~/.local/share/flybo`): what must be kept. The
  embedded service's SQLite database and filesystem broker, the local artifact store
  (`artifacts/`) and the stored areas (`areas/`).
- `cache_dir` (`FLYBO_CACHE_DIR`, default `~/.cache/flybo`): what can be rebuilt. Downloaded
  copies of remote artifacts (`artifacts/`); the areas' ground truth and thumbnails live there
  too (`areas.cache`).

Without the variables, the areas library (`areas.store`, `areas.cache`) uses the same defaults
on its own, so `flybo run` and `flybo areas import` see the areas the service stored.
Scale-out sets `FLYBO_DATABASE_URL`, `FLYBO_BROKER_URL` and `FLYBO_ARTIFACT_URL` (see
`docs/service.md`).
"""

from __future__ import annotations

import hashlib
import hmac
from functools import cached_property
from pathlib import Path
from typing import Literal

from pydantic import Field, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

# Known only to development setups; production refuses to start with it.
DEVELOPMENT_SECRET = "development-only-secret-do-not-use-in-production"


# Every built-in area has a held-out counterpart by default.
HELDOUT_DEFAULT_AREAS = ("facility-a", "facility-b", "facility-c", "maze", "offices-a",
                         "offices-b", "offices-c", "platform-a", "platform-b", "powerplant",
                         "warehouse")


# A run is told to stop (and fails cleanly) this long before its hard limit kills its process;
# a quarter of the limit when that is shorter.
SOFT_TIME_LIMIT_MARGIN_S = 60.0


def default_data_dir() -> Path:
    """`data_dir` when `FLYBO_DATA_DIR` is not set (the rule of `areas.store.areas_dir` too)."""
    return Path.home() / ".local" / "share" / "flybo"


def default_cache_dir() -> Path:
    """`cache_dir` when `FLYBO_CACHE_DIR` is not set (the rule of `areas.cache.cache_dir` too)."""
    return Path.home() / ".cache" / "flybo"


def insecure_sandbox_refusal(environment: str, allow_insecure: bool) -> str | None:
    """Why the sandbox settings are refused (the insecure fallback in production), or None."""
    if allow_insecure and environment == "production":
        return ("FLYBO_SANDBOX_ALLOW_INSECURE is set while FLYBO_ENVIRONMENT=production: the "
                "insecure fallback runs uploaded planners without containing them and is for "
                "development only; unset it and give this machine the full sandbox "
                "(docs/sandbox.md)")
    return None


class Settings(BaseSettings):
    """Everything the API, the workers and the CLI client are configured by."""

    model_config = SettingsConfigDict(env_prefix="FLYBO_", extra="ignore")

    environment: Literal["development", "production"] = "development"
    data_dir: Path = Field(default_factory=default_data_dir,
                           description="what must be kept: database, broker, artifacts, areas")
    cache_dir: Path = Field(default_factory=default_cache_dir,
                            description="what can be rebuilt: downloaded artifacts")
    database_url: str | None = Field(default=None, description="SQLAlchemy URL; default SQLite")
    broker_url: str | None = Field(default=None, description="Celery broker; default filesystem")
    artifact_url: str | None = Field(
        default=None, description="file:///folder or s3://bucket/prefix; default data_dir/artifacts"
    )
    s3_endpoint_url: str | None = None
    redis_url: str | None = Field(
        default=None, description="Redis for what API processes share (rate limits, the "
        "leaderboard cache's version); default the broker's URL when it is a Redis one")
    api_workers: int | None = Field(
        default=None, ge=1, le=64, description="API processes of `flybo serve`; default the "
        "usable cores in production (with Redis), else 1")
    secret_key: str = Field(default=DEVELOPMENT_SECRET, description="keys the token hashes")
    # The held-out split (`server.heldout`): its areas' layout seeds and names are HMACs of
    # this secret, the benchmark version, the generation and the area; keep it fixed for a
    # benchmark version (changing it makes other areas) and rotate with `flybo heldout rotate`.
    heldout_secret: str | None = Field(
        default=None, description="keys the held-out areas' seeds and names; default: a key "
        "derived from secret_key")
    heldout_areas: list[str] = Field(
        default_factory=lambda: list(HELDOUT_DEFAULT_AREAS),
        description="the built-in areas whose generator makes a held-out area each")

    # Uploads.
    max_area_upload_mib: float = Field(default=200.0, gt=0)

    # Fairness: per user, 0 disables a quota.
    quota_jobs_per_day: int = Field(default=50, ge=0)
    quota_concurrent_runs: int = Field(default=40, ge=0)
    max_runs_per_job: int = Field(default=200, ge=1)
    max_seconds_per_run: float = Field(default=3600.0, gt=0)

    # The 3D replay (web/replay): a viser server beside the API.
    viewer_port: int = Field(default=8080, ge=1, le=65535)
    viewer_url: str = Field(default="http://127.0.0.1:8080",
                            description="the viewer's address as browsers reach it")

    # HTTP protections (server/middleware.py).
    rate_limit_writes_per_minute: float = Field(default=120.0, ge=0, description="0: off")
    rate_limit_auth_failures_per_minute: float = Field(default=30.0, gt=0)
    rate_limit_burst: int = Field(default=60, ge=1)
    cors_origins: list[str] = Field(default_factory=list,
                                    description="origins allowed cross-origin; none by default")

    # Uploaded planners and the sandbox.
    max_planner_upload_mib: float = Field(default=1.0, gt=0)
    max_planner_unpacked_mib: float = Field(default=10.0, gt=0)
    max_planner_files: int = Field(default=200, ge=1)
    sandbox_builtin: bool = Field(default=False,
                                  description="run built-in planners in the sandbox too")
    sandbox_plan_timeout_s: float = Field(default=10.0, gt=0)
    sandbox_memory_mib: int = Field(default=2048, ge=256)
    sandbox_allow_insecure: bool = Field(
        default=False,
        description="run uploaded planners even without full isolation (development only: the "
                    "fallback does not contain hostile code); refused in production")
    max_concurrent_checks: int = Field(
        default=2, ge=1, description="uploads compiled and dry-run at once, per API process")

    # Workers.
    heartbeat_interval_s: float = Field(default=3.0, gt=0)
    heartbeat_timeout_s: float = Field(default=60.0, gt=0)
    requeue_queued_after_s: float = Field(default=300.0, gt=0)
    sweep_interval_s: float = Field(default=15.0, gt=0)
    max_attempts: int = Field(default=3, ge=1)
    # Wall-time limits per run: a floor plus a multiple of its simulated seconds.
    run_time_limit_base_s: float = Field(default=300.0, gt=0)
    run_time_limit_per_sim_s: float = Field(default=1.0, gt=0)

    @model_validator(mode="after")
    def _refuse_insecure_production(self) -> Settings:
        insecure = self.secret_key == DEVELOPMENT_SECRET or len(self.secret_key) < 32
        if self.environment == "production" and insecure:
            raise ValueError(
                "FLYBO_SECRET_KEY must be set to a random string of at least 32 characters "
                "when FLYBO_ENVIRONMENT=production"
            )
        if self.heldout_secret is not None and len(self.heldout_secret) < 32 \
                and self.environment == "production":
            raise ValueError("FLYBO_HELDOUT_SECRET must be at least 32 characters long")
        refusal = insecure_sandbox_refusal(self.environment, self.sandbox_allow_insecure)
        if refusal is not None:
            raise ValueError(refusal)
        return self

    @property
    def heldout_key(self) -> bytes:
        """The key of the held-out seeds: `heldout_secret`, else derived from `secret_key`
        (which production requires), so a deployment has held-out areas of its own."""
        if self.heldout_secret is not None:
            return self.heldout_secret.encode()
        return hmac.new(self.secret_key.encode(), b"flybo held-out split",
                        hashlib.sha256).digest()

    @cached_property
    def resolved_data_dir(self) -> Path:
        return self.data_dir.expanduser().resolve()

    @cached_property
    def resolved_cache_dir(self) -> Path:
        return self.cache_dir.expanduser().resolve()

    @property
    def areas_dir(self) -> Path:
        """Stored (uploaded or imported) areas, one `.npz` file each (`areas.store`)."""
        return self.resolved_data_dir / "areas"

    @property
    def artifacts_dir(self) -> Path:
        """The local artifact store, unless `artifact_url` names another."""
        return self.resolved_data_dir / "artifacts"

    @property
    def artifact_cache_dir(self) -> Path:
        """Local copies of artifacts from a remote (S3) store."""
        return self.resolved_cache_dir / "artifacts"

    @property
    def db_url(self) -> str:
        if self.database_url:
            return self.database_url
        return f"sqlite:///{self.resolved_data_dir / 'flybo.sqlite'}"

    @property
    def broker(self) -> str:
        return self.broker_url or "filesystem://"

    @property
    def broker_folder(self) -> Path:
        """Where the filesystem broker keeps its messages (used only with `filesystem://`)."""
        return self.resolved_data_dir / "broker"

    @property
    def artifacts(self) -> str:
        if self.artifact_url:
            return self.artifact_url
        return self.artifacts_dir.as_uri()

    @property
    def shared_redis_url(self) -> str | None:
        """The Redis that holds what the API processes share, or None: then each process
        keeps its own (the embedded default, one API process)."""
        if self.redis_url:
            return self.redis_url
        if self.broker_url and self.broker_url.startswith(("redis://", "rediss://")):
            return self.broker_url
        return None

    def default_api_workers(self, usable_cores: int) -> int:
        """API processes when `--api-workers` is not given: one per core in production when
        Redis holds the shared counters; one otherwise (see `flybo serve`)."""
        if self.api_workers is not None:
            return self.api_workers
        if self.environment == "production" and self.shared_redis_url is not None:
            return max(1, usable_cores)
        return 1

    @property
    def max_area_upload_bytes(self) -> int:
        return int(self.max_area_upload_mib * 1024 * 1024)

    def run_time_limit_s(self, sim_seconds: float) -> float:
        """Hard wall-time limit of one run of `sim_seconds` simulated seconds: past it, the
        worker process running it is killed."""
        return self.run_time_limit_base_s + self.run_time_limit_per_sim_s * sim_seconds

    def run_soft_time_limit_s(self, sim_seconds: float) -> float:
        """Soft wall-time limit of that run: past it, the run is stopped and fails cleanly."""
        hard = self.run_time_limit_s(sim_seconds)
        return hard - min(SOFT_TIME_LIMIT_MARGIN_S, hard / 4)


def load_settings() -> Settings:
    return Settings()
