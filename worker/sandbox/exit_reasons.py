"""Why a planner process ended, in words for the run's record: the limit it hit, the signal
that killed it, or its exit code."""

from __future__ import annotations

import signal
from pathlib import Path

from worker.sandbox.cgroups import Cgroups
from worker.sandbox.limits import SandboxLimits

STDERR_TAIL_BYTES = 4000
_SIGNALS = {signal.SIGXCPU: "exceeded its CPU time limit",
            signal.SIGXFSZ: "exceeded its file size limit (too much output)",
            signal.SIGSEGV: "crashed (segmentation fault)"}


def stderr_tail(path: Path) -> str:
    """The last `STDERR_TAIL_BYTES` of the planner's output file."""
    try:
        with path.open("rb") as fh:
            fh.seek(max(0, path.stat().st_size - STDERR_TAIL_BYTES))
            return fh.read().decode(errors="replace")
    except OSError:
        return ""


def exit_reason(code: int | None, what: str, *, stderr_path: Path, limits: SandboxLimits,
                cgroups: Cgroups | None, memory_cgroup: bool) -> str:
    """Why the process that ended with `code` (negative: the signal) did, during `what`."""
    try:
        written = stderr_path.stat().st_size
    except OSError:
        written = 0
    if written >= limits.file_size_mib * 1024 * 1024 - 1_000_000:
        return (f"the planner process exceeded its file size limit (too much output, "
                f"{limits.file_size_mib} MiB) during {what}")
    if cgroups is not None and cgroups.oom_killed():
        return f"the planner exceeded its memory limit of {limits.memory_mib} MiB"
    tail = stderr_tail(stderr_path)
    if "Resource temporarily unavailable" in tail or ("fork" in tail
                                                      and "BlockingIOError" in tail):
        return f"the planner exceeded its process limit of {limits.processes}"
    if code is not None and code < 0:
        sig = signal.Signals(-code)
        reason = _SIGNALS.get(sig, f"was killed by {sig.name}")
        if sig == signal.SIGKILL and not memory_cgroup:
            reason = "was killed (memory or another limit)"
        return f"the planner process {reason} during {what}"
    return f"the planner process exited (code {code}) during {what}"
