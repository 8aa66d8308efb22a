"""Planning time charged in CPU time, counted by the runner: a planner that computes is charged
for every thread it keeps busy, one that sleeps is not charged for sleeping."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import numba
import numpy as np
import numpy.typing as npt
import pytest

from areas import load_area, load_ground_truth
from sim.compile_clock import (
    compiling_seconds,
    compiling_wall_seconds,
    cpu_seconds_less_compiling,
)
from sim.config import preset
from sim.episode import run_episode
from sim.interface import Observation, Plan, PlannerContext
from sim.planning_charge import PlanningCharge


def _spin(seconds: float) -> None:
    end = time.thread_time() + seconds
    while time.thread_time() < end:
        pass


class _Hover:
    """Plans to stay where it is; `think` is what it does while it plans."""

    def __init__(self, think: str) -> None:
        self.think = think

    def reset(self, ctx: PlannerContext) -> None:
        pass

    def plan(self, obs: Observation) -> Plan:
        if self.think == "sleep":
            time.sleep(0.2)
        elif self.think == "threads":
            helper = threading.Thread(target=_spin, args=(0.2,))
            helper.start()
            helper.join()
        p = obs.pose.position
        return Plan(waypoints=np.array([[p[0], p[1], p[2], obs.pose.yaw]]))


@pytest.mark.parametrize(("think", "low", "high"), [("sleep", 0.0, 0.05),
                                                    ("threads", 0.18, 0.5)])
def test_cpu_time_is_charged_not_sleep(think: str, low: float, high: float) -> None:
    area = load_area("maze")
    cfg = preset("default").model_copy(update={"startup_spin": False})
    result = run_episode(area, load_ground_truth(area), _Hover(think), cfg, 0, seconds=1.5,
                         speed_factor=1.0)
    assert result.iterations >= 2
    charged = result.charged_s[1:]  # the first call also pays for what it loads
    assert np.all((charged >= low) & (charged <= high)), charged
    payload = result.to_json()["planning_charge"]
    assert payload["mode"] == "cpu" and payload["speed_factor"] == 1.0
    assert payload["clock"] == "process"


def test_the_speed_factor_scales_the_charge() -> None:
    slow = PlanningCharge("cpu", 0.5, object())
    assert slow.seconds(wall_s=1.0, cpu_s=0.4) == pytest.approx(0.2)
    assert PlanningCharge("wall", 0.5, object()).seconds(1.0, 0.4) == 1.0
    assert PlanningCharge("none", 1.0, object()).seconds(1.0, 0.4) == 0.0
    with pytest.raises(ValueError, match="speed factor"):
        PlanningCharge("cpu", 0.0, object())


class _Sandboxed:
    def __init__(self) -> None:
        self.used = 0.0

    def cpu_seconds(self) -> float:
        self.used += 0.25
        return self.used


def test_a_planner_in_another_process_is_charged_by_its_own_clock() -> None:
    charge = PlanningCharge("cpu", 1.0, _Sandboxed())
    before = charge.cpu_seconds()
    assert charge.seconds(0.0, charge.cpu_seconds() - before) == pytest.approx(0.25)
    assert charge.describe()["clock"] == "sandbox"
    assert "compiling_left_out_s" not in charge.describe()


def _fresh_kernel() -> Callable[[npt.NDArray[np.float64]], float]:
    """A numba kernel no cache holds (defined per call, cache off): its first call compiles."""

    @numba.njit(cache=False)
    def kernel(values: npt.NDArray[np.float64]) -> float:  # pragma: no cover - numba
        total = 0.0
        for i in range(values.shape[0]):
            for j in range(i % 7):
                total += np.sin(values[i]) * np.cos(values[i] + j) / (1.0 + j)
        return total

    return kernel


class _Compiles(_Hover):
    """Compiles a new numba kernel in its first planning call (`compiled_s`: the CPU time
    numba's compiler took), then only calls it."""

    def __init__(self) -> None:
        super().__init__("none")
        self.kernel = _fresh_kernel()
        self.compiled_s = 0.0

    def plan(self, obs: Observation) -> Plan:
        before = compiling_seconds()
        self.kernel(np.linspace(0.0, 1.0, 100))
        self.compiled_s += compiling_seconds() - before
        return super().plan(obs)


def test_compiling_numba_kernels_is_left_out_of_the_cpu_clock() -> None:
    kernel = _fresh_kernel()
    cpu0, less0, compiling0 = time.process_time(), cpu_seconds_less_compiling(), compiling_seconds()
    wall0 = compiling_wall_seconds()
    kernel(np.linspace(0.0, 1.0, 100))
    spent = time.process_time() - cpu0
    compiled = compiling_seconds() - compiling0
    assert compiled > 0.05 and compiled <= spent + 1e-3, (compiled, spent)
    assert compiling_wall_seconds() - wall0 >= 0.5 * compiled
    assert cpu_seconds_less_compiling() - less0 < 0.2 * spent
    # Called again, nothing compiles.
    compiling1 = compiling_seconds()
    kernel(np.linspace(0.0, 1.0, 100))
    assert compiling_seconds() == compiling1


@pytest.mark.parametrize("mode", ["cpu", "wall", "none"])
def test_a_planner_is_neither_charged_nor_timed_for_compiling(mode: str) -> None:
    area = load_area("maze")
    cfg = preset("default").model_copy(update={"startup_spin": False,
                                               "planning_time_charge": mode})
    planner = _Compiles()
    result = run_episode(area, load_ground_truth(area), planner, cfg, 0, seconds=1.0,
                         speed_factor=1.0)
    assert planner.compiled_s > 0.05
    assert result.planning_times_ms[0] / 1000 < 0.2 * planner.compiled_s, result.planning_times_ms
    assert result.charged_s[0] < 0.2 * planner.compiled_s, result.charged_s
    payload = result.to_json()["planning_charge"]
    if mode == "none":
        assert payload == {"mode": "none", "total_s": 0.0, "per_call_s": payload["per_call_s"]}
    else:
        assert payload["compiling_left_out_s"] >= planner.compiled_s
