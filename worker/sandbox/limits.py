"""The resource limits of one planner process, and how they are applied to it as it starts:
its cgroups joined, its rlimits set (`preexec`)."""

from __future__ import annotations

import os
import resource
from collections.abc import Callable
from typing import TYPE_CHECKING

from pydantic import BaseModel, Field

if TYPE_CHECKING:
    from worker.sandbox.cgroups import Cgroups
    from worker.sandbox.isolation import Isolation


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


def preexec(limits: SandboxLimits, cgroups: Cgroups, iso: Isolation) -> Callable[[], None]:
    """Runs in the forked child before exec: join the cgroups, set the rlimits."""
    targets = [str(p / "cgroup.procs") for p in cgroups.paths]

    def apply() -> None:
        pid = str(os.getpid())
        for target in targets:
            with open(target, "w") as fh:
                fh.write(pid)
        mib = 1024 * 1024
        resource.setrlimit(resource.RLIMIT_CPU, (limits.cpu_seconds, limits.cpu_seconds + 5))
        resource.setrlimit(resource.RLIMIT_NOFILE, (limits.open_files, limits.open_files))
        resource.setrlimit(resource.RLIMIT_FSIZE, (limits.file_size_mib * mib,) * 2)
        resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
        resource.setrlimit(resource.RLIMIT_NPROC, (limits.processes, limits.processes))
        if iso.cgroup_memory is None:
            # Address space, not resident memory: generous, since numba and BLAS reserve a lot.
            space = 4 * limits.memory_mib * mib
            resource.setrlimit(resource.RLIMIT_AS, (space, space))

    return apply
