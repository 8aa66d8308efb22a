"""What isolation this machine offers uploaded code (`worker.sandbox.isolation.probe` finds it)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path


@dataclass(frozen=True)
class Isolation:
    """What this machine offers: bubblewrap with namespaces, and which cgroup controllers."""

    bwrap: str | None
    namespaces: bool
    cgroup_pids: Path | None
    cgroup_memory: Path | None
    notes: list[str] = field(default_factory=list)
    # The seccomp filter (`seccomp_filter`) is loaded: a further layer, not needed for `full`.
    seccomp: bool = False

    @property
    def full(self) -> bool:
        """Bubblewrap with namespaces, and the pids and memory cgroups: what uploaded code
        needs."""
        return bool(self.bwrap and self.namespaces and self.cgroup_pids is not None
                    and self.cgroup_memory is not None)
