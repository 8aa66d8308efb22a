"""The CPU time of a sandboxed planner, as the episode runner charges it: read from the kernel
for every thread of the planner process, not taken from anything the planner reports."""

from __future__ import annotations

from pathlib import Path

import pytest

from sim.config import preset
from sim.episode import run_episode
from sim.interface import Observation, Plan, PlannerContext
from worker.sandbox import isolation
from worker.sandbox.dry_run import tiny_area
from worker.sandbox.isolation import Isolation, SandboxLimits
from worker.sandbox.proxy import SandboxedPlanner

pytestmark = pytest.mark.slow  # each test starts the sandbox and flies

# Each plan call does `WORK` for 0.3 s, then holds position; the fourth call ends the run.
PLANNER = '''
import threading
import time

import numpy as np

from planners.api import Plan, Planner


def burn(seconds):
    end = time.thread_time() + seconds
    while time.thread_time() < end:
        pass


class Work(Planner):
    calls = 0

    def plan(self, obs):
        self.calls += 1
        if self.calls > 3:
            return Plan.finished("done")
        {work}
        return Plan(np.array([[*obs.pose.position, obs.pose.yaw]]))
'''
# Busy in a second thread, so that the main thread's own clock would see none of it.
BURN = "worker = threading.Thread(target=burn, args=(0.3,)); worker.start(); worker.join()"
SLEEP = "time.sleep(0.3)"


class _Charging:
    """Reads the sandbox's CPU seconds around each plan call, as the episode runner does."""

    def __init__(self, inner: SandboxedPlanner) -> None:
        self.inner = inner
        self.charged: list[float] = []

    def reset(self, ctx: PlannerContext) -> None:
        self.inner.reset(ctx)

    def plan(self, obs: Observation) -> Plan:
        before = self.inner.cpu_seconds()
        plan = self.inner.plan(obs)
        self.charged.append(self.inner.cpu_seconds() - before)
        return plan


def _charges(tmp_path: Path, work: str) -> list[float]:
    """The CPU seconds charged to each of the first three plan calls, the planner process's
    reset (inside the first call) not counted."""
    code = tmp_path / "code"
    code.mkdir()
    (code / "planner.py").write_text(PLANNER.format(work=work))
    area, truth = tiny_area()
    config = preset("exact").model_copy(update={"startup_spin": False})
    with SandboxedPlanner(code=code, limits=SandboxLimits(plan_timeout_s=5.0)) as boxed:
        charging = _Charging(boxed)
        assert boxed.cpu_seconds() == 0.0  # not started yet
        run_episode(area, truth, charging, config, 0, seconds=10.0)
        total = boxed.cpu_seconds()
    assert boxed.cpu_seconds() == total  # closed: the last reading stays
    assert len(charging.charged) == 4
    assert all(c >= 0.0 for c in charging.charged)
    assert total >= sum(charging.charged)
    assert 0.0 <= boxed.reset_cpu_seconds <= charging.charged[0]
    return [charging.charged[0] - boxed.reset_cpu_seconds, *charging.charged[1:3]]


@pytest.mark.parametrize("mode", ["probed", "fallback"])
def test_cpu_burnt_in_a_second_thread_is_charged(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, mode: str
) -> None:
    if mode == "fallback":  # no bubblewrap and no cgroups: the process tree alone
        monkeypatch.setattr(isolation, "probe", lambda: Isolation(None, False, None, None))
        monkeypatch.setenv("FLYBO_SANDBOX_ALLOW_INSECURE", "1")  # uploaded code needs it there
    charged = _charges(tmp_path, BURN)
    assert all(c >= 0.25 for c in charged), charged
    # The busy loop takes 0.3 s of CPU; the rest of a call is the map copy and messages.
    assert all(c < 0.6 for c in charged), charged


def test_sleeping_is_not_charged(tmp_path: Path) -> None:
    charged = _charges(tmp_path, SLEEP)
    assert all(c < 0.05 for c in charged), charged

