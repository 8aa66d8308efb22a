"""Planner cgroups left behind by a process that is gone (a worker killed before it cleaned up)
are swept when a process first finds full isolation, killing what they still hold; those of live
processes, which may share the cgroup root, are left alone, and one whose owner is unknown is
removed only when it is empty."""

from __future__ import annotations

import os
import subprocess
import time
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest

from worker.sandbox import cgroups, isolation
from worker.sandbox.isolation import probe


class Planted:
    """Cgroups made in the sandbox's roots by this test, each optionally holding a sleeper."""

    def __init__(self) -> None:
        self.iso = probe()
        self.sleepers: list[subprocess.Popen[bytes]] = []
        self.paths: list[Path] = []

    def cgroup(self, name: str, *, holding: bool) -> tuple[list[Path], subprocess.Popen[bytes]
                                                           | None]:
        paths = []
        for root in (self.iso.cgroup_pids, self.iso.cgroup_memory):
            assert root is not None
            path = root / name
            path.mkdir(exist_ok=True)
            paths.append(path)
        self.paths += paths
        if not holding:
            return paths, None
        sleeper = subprocess.Popen(["sleep", "600"])
        self.sleepers.append(sleeper)
        for path in paths:
            (path / "cgroup.procs").write_text(str(sleeper.pid))
        return paths, sleeper

    def close(self) -> None:
        for sleeper in self.sleepers:
            sleeper.kill()
            sleeper.wait()
        for path in self.paths:
            cgroups._remove_cgroup(path)


@pytest.fixture
def planted(isolated: None) -> Iterator[Planted]:
    plants = Planted()
    yield plants
    plants.close()


def _dead_owner() -> str:
    """The `PID-START` of a process that has ended."""
    gone = subprocess.Popen(["sleep", "0"])
    start = cgroups._start_time(gone.pid)
    gone.wait()
    return f"{gone.pid}-{start}"


def test_a_gone_process_s_cgroups_are_swept_and_a_live_one_s_kept(planted: Planted) -> None:
    tag = uuid.uuid4().hex[:8]
    me = f"{os.getpid()}-{cgroups._start_time(os.getpid())}"
    dead, dead_sleeper = planted.cgroup(f"sbx-{_dead_owner()}-{tag}", holding=True)
    live, live_sleeper = planted.cgroup(f"sbx-{me}-{tag}", holding=True)
    unknown_empty, _ = planted.cgroup(f"sbx-{tag}old1", holding=False)
    unknown_busy, unknown_sleeper = planted.cgroup(f"sbx-{tag}old2", holding=True)
    removed = cgroups.sweep_stale(planted.iso)
    assert set(dead) <= set(removed) and not any(path.exists() for path in dead)
    assert dead_sleeper is not None and dead_sleeper.wait(timeout=5) == -9  # killed
    # A live process's cgroups: untouched. Owner-less ones this young: perhaps just made.
    assert all(path.exists() for path in live + unknown_empty + unknown_busy)
    assert live_sleeper is not None and live_sleeper.poll() is None
    # Old enough, an owner-less one goes when empty and stays while it holds a process.
    old = time.time() - cgroups.UNKNOWN_OWNER_AGE_S - 60
    for path in unknown_empty + unknown_busy:
        os.utime(path, (old, old))
    removed = cgroups.sweep_stale(planted.iso)
    assert set(unknown_empty) <= set(removed)
    assert not any(path.exists() for path in unknown_empty)
    assert all(path.exists() for path in live + unknown_busy)
    assert unknown_sleeper is not None and unknown_sleeper.poll() is None


def test_the_first_full_probe_sweeps(planted: Planted, monkeypatch: pytest.MonkeyPatch) -> None:
    dead, sleeper = planted.cgroup(f"sbx-{_dead_owner()}-{uuid.uuid4().hex[:8]}", holding=True)
    monkeypatch.setattr(isolation, "_full_isolation", None)
    assert isolation.probe().full
    assert not any(path.exists() for path in dead)
    assert sleeper is not None and sleeper.wait(timeout=5) == -9


def test_a_sandbox_s_cgroups_name_their_owner(planted: Planted) -> None:
    made = cgroups.make_cgroups(planted.iso, isolation.SandboxLimits())
    planted.paths += made.paths
    name = made.paths[0].name
    assert cgroups._owner_alive(name) is True
    assert name.startswith(f"sbx-{os.getpid()}-")
    made.cleanup()
    assert not any(path.exists() for path in made.paths)
