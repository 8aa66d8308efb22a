"""The resource limits of one planner process (applied as it starts by
`worker.sandbox.cgroups.preexec`)."""

from __future__ import annotations

from pydantic import BaseModel, Field


class SandboxLimits(BaseModel):
    """Resource limits of one planner process."""

    memory_mib: int = Field(default=2048, ge=256)
    processes: int = Field(default=64, ge=8, description="threads count too")
    cpu_seconds: int = Field(default=3600, ge=10)
    open_files: int = Field(default=256, ge=32)
    file_size_mib: int = Field(default=64, ge=1)
    scratch_mib: int = Field(default=256, ge=16,
                             description="each writable folder: /sandbox/work, /tmp, /dev/shm")
    start_timeout_s: float = Field(default=60.0, gt=0)
    plan_timeout_s: float = Field(default=10.0, gt=0)
    run_planning_budget_s: float = Field(default=1800.0, gt=0)

