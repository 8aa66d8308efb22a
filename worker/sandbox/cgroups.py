"""The pids and memory cgroups of planner processes: found writable (`cgroup_root`), made one per
process with its limits (`make_cgroups`), joined with the rlimits set as the process starts
(`preexec`), and removed once empty, after what is left in them is killed.

A cgroup's name says which process made it (`sbx-PID-START-RANDOM`, START the process's start
time, so that a reused PID is not taken for it): `sweep_stale` removes those of processes that
are gone (a worker killed before it could clean up), killing what they still hold, and leaves
alone those of live processes, which may share the same cgroup root (the API and the workers
on one machine)."""

from __future__ import annotations

import contextlib
import os
import resource
import threading
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from worker.sandbox.isolation_level import Isolation
from worker.sandbox.limits import SandboxLimits

CGROUP_V1 = Path("/sys/fs/cgroup")


def cgroup_root(controller: str) -> Path | None:
    for candidate in (CGROUP_V1 / controller / "flybo-sandbox", CGROUP_V1 / "flybo-sandbox"):
        try:
            candidate.mkdir(parents=True, exist_ok=True)
        except OSError:
            continue
        limit_file = {"pids": "pids.max", "memory": "memory.limit_in_bytes"}[controller]
        if candidate.parent == CGROUP_V1:  # cgroup v2: one hierarchy
            limit_file = {"pids": "pids.max", "memory": "memory.max"}[controller]
            for parent in (CGROUP_V1, candidate):  # the controller must reach our children
                with contextlib.suppress(OSError):
                    (parent / "cgroup.subtree_control").write_text(f"+{controller}")
        probe = candidate / f"probe-{uuid.uuid4().hex[:8]}"
        try:
            probe.mkdir()
            try:
                # Writable, not merely there: a limit that cannot be set is no limit.
                (probe / limit_file).write_text("64" if controller == "pids" else "268435456")
                ok = True
            finally:
                probe.rmdir()
        except OSError:
            ok = False
        if ok:
            return candidate
    return None


@dataclass
class Cgroups:
    """The cgroups of one planner process, removed by `cleanup`."""

    paths: list[Path]
    memory: Path | None

    def oom_killed(self) -> bool:
        if self.memory is None:
            return False
        for name in ("memory.oom_control", "memory.events"):
            path = self.memory / name
            if path.exists():
                for line in path.read_text().splitlines():
                    key, _, value = line.partition(" ")
                    if key == "oom_kill" and value.strip() not in ("", "0"):
                        return True
        failcnt = self.memory / "memory.failcnt"
        return failcnt.exists() and failcnt.read_text().strip() not in ("", "0")

    def cleanup(self, wait_s: float = 2.0) -> None:
        """Kill what is left in the cgroups and remove them. A cgroup stays busy until its
        killed processes are reaped; one still busy after `wait_s` is removed by a later
        `make_cgroups` instead of being left behind."""
        remaining = list(self.paths)
        deadline = time.monotonic() + wait_s
        while True:
            remaining = [path for path in remaining if not _remove_cgroup(path)]
            if not remaining or time.monotonic() >= deadline:
                break
            time.sleep(0.02)
        with _stale_lock:
            _stale_cgroups.extend(remaining)


# Cgroups of this process that were still busy when their sandbox closed.
_stale_cgroups: list[Path] = []
_stale_lock = threading.Lock()


def _remove_cgroup(path: Path) -> bool:
    """Kill the processes in cgroup `path` and remove it; whether it is gone."""
    try:
        for pid in (path / "cgroup.procs").read_text().split():
            with contextlib.suppress(ProcessLookupError, ValueError):
                os.kill(int(pid), 9)
        path.rmdir()
    except FileNotFoundError:
        return True
    except OSError:
        return False
    return True


# A cgroup named without its owner is taken as left behind only after this long.
UNKNOWN_OWNER_AGE_S = 600.0


def _start_time(pid: int) -> str | None:
    """When process `pid` started (clock ticks since boot), or None when there is none."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return stat.rpartition(")")[2].split()[19]  # the 22nd field; the name may hold spaces


def _owner_alive(name: str) -> bool | None:
    """Whether the process that made cgroup `name` still runs; None when the name does not
    say (one made before names held their owner)."""
    parts = name.split("-")
    if len(parts) != 4 or parts[0] != "sbx" or not parts[1].isdigit():
        return None
    return _start_time(int(parts[1])) == parts[2]


def sweep_stale(iso: Isolation) -> list[Path]:
    """Remove the planner cgroups of processes that are gone, killing what is left in them;
    the ones removed. A cgroup whose owner is unknown is removed only when empty and older
    than `UNKNOWN_OWNER_AGE_S`."""
    removed = []
    for root in {iso.cgroup_pids, iso.cgroup_memory} - {None}:
        assert root is not None
        try:
            children = [path for path in root.iterdir()
                        if path.is_dir() and path.name.startswith("sbx-")]
        except OSError:
            continue
        for path in children:
            alive = _owner_alive(path.name)
            if alive:
                continue
            if alive is None:
                # Perhaps just made by a process that is about to join it: only an old one.
                with contextlib.suppress(OSError):
                    if time.time() - path.stat().st_mtime > UNKNOWN_OWNER_AGE_S:
                        path.rmdir()  # the kernel refuses while it holds a process
                gone = not path.exists()
            else:
                gone = _remove_cgroup(path)
                deadline = time.monotonic() + 2.0
                while not gone and time.monotonic() < deadline:  # killed, not yet reaped
                    time.sleep(0.02)
                    gone = _remove_cgroup(path)
            if gone:
                removed.append(path)
    return removed


def make_cgroups(iso: Isolation, limits: SandboxLimits) -> Cgroups:
    with _stale_lock:
        _stale_cgroups[:] = [path for path in _stale_cgroups if not _remove_cgroup(path)]
    start = _start_time(os.getpid())
    owner = f"{os.getpid()}-{start}-" if start is not None else ""  # else: an unknown owner's
    name = f"sbx-{owner}{uuid.uuid4().hex[:12]}"
    paths: list[Path] = []
    memory: Path | None = None
    if iso.cgroup_pids is not None:
        path = iso.cgroup_pids / name
        path.mkdir()
        (path / "pids.max").write_text(str(limits.processes))
        paths.append(path)
    if iso.cgroup_memory is not None:
        path = iso.cgroup_memory / name
        if not path.exists():
            path.mkdir()
        limit = str(limits.memory_mib * 1024 * 1024)
        for fname in ("memory.limit_in_bytes", "memory.max"):
            if (path / fname).exists():
                (path / fname).write_text(limit)
        swap = path / "memory.memsw.limit_in_bytes"
        if swap.exists():
            with contextlib.suppress(OSError):
                swap.write_text(limit)
        if path not in paths:
            paths.append(path)
        memory = path
    return Cgroups(paths, memory)


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
