"""CPU seconds of a sandbox's processes, as the kernel counts them (`/proc/PID/stat`)."""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

CLOCK_TICKS = os.sysconf("SC_CLK_TCK")


def cpu_seconds(pid: int, cgroups: Iterable[Path]) -> float:
    """User + system seconds of process `pid`, every process below it and every process in
    `cgroups`: each process's count covers all its threads (the exited ones too) plus its
    children it has waited for."""
    pids = descendants(pid)
    for path in cgroups:
        pids.update(cgroup_pids(path))
    return sum(cpu_ticks(each) for each in pids) / CLOCK_TICKS


def cpu_ticks(pid: int) -> int:
    """utime + stime + cutime + cstime of process `pid` in clock ticks; 0 if it is gone."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as fh:
            stat = fh.read()
    except OSError:
        return 0
    # The command name (field 2) may hold spaces and parentheses: count from its last ')'.
    fields = stat[stat.rfind(b")") + 2:].split()
    try:
        return sum(int(value) for value in fields[11:15])  # fields 14 to 17
    except ValueError:
        return 0


def descendants(pid: int) -> set[int]:
    """`pid` and the processes below it, from `/proc/PID/task/TID/children`."""
    found: set[int] = set()
    todo = [pid]
    while todo:
        current = todo.pop()
        if current in found:
            continue
        found.add(current)
        try:
            tasks = os.listdir(f"/proc/{current}/task")
        except OSError:
            continue
        for tid in tasks:
            try:
                with open(f"/proc/{current}/task/{tid}/children", "rb") as fh:
                    todo.extend(int(child) for child in fh.read().split())
            except (OSError, ValueError):
                continue
    return found


def cgroup_pids(path: Path) -> set[int]:
    """The processes in cgroup `path`; none if it is gone."""
    try:
        return {int(pid) for pid in (path / "cgroup.procs").read_text().split()}
    except (OSError, ValueError):
        return set()
