"""What a planner's thinking costs on the simulated clock.

While a planner thinks, the simulated clock runs on (the vehicle hovers, or flies on along its
trajectory when asked mid-flight), as in a real-time system. The benchmark's presets charge the
CPU time the planner used for the call, counted by the runner and never reported by the planner:
for a planner in this process, the process's CPU time over the call (every thread); for one in
a sandbox, the sandbox's processes' CPU time as the kernel counts it (its `cpu_seconds()`).
The CPU time is scaled by the machine's speed factor (`sim.reference_speed`), so a charged
second is a second of the reference machine whatever the load or the machine. In this process,
the time numba spends in its compiler is left out (`sim.compile_clock`): it depends on the
installation's kernel cache, not on the method.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Literal, NamedTuple

from sim.compile_clock import compiler_spent, cpu_seconds_less_compiling

ChargeMode = Literal["cpu", "wall", "none"]


class ClockReading(NamedTuple):
    """The clocks at a call's start: `cpu_s` the charged CPU clock; `compiling_s` and
    `compiling_wall_s` the CPU and wall time numba's compiler has taken in this process (left
    out of the call's charge and of its thinking time)."""

    cpu_s: float
    compiling_s: float
    compiling_wall_s: float


class PlanningCharge:
    """The charge of one run's `plan` calls (mode and speed factor fixed for the run)."""

    def __init__(self, mode: ChargeMode, speed_factor: float, planner: object) -> None:
        if not speed_factor > 0:
            raise ValueError(f"speed factor must be positive, got {speed_factor}")
        self.mode, self.speed_factor = mode, float(speed_factor)
        clock = getattr(planner, "cpu_seconds", None)
        self.external = callable(clock)
        # Only the 'cpu' mode reads a clock; the others never touch the planner's.
        self.cpu_seconds: Callable[[], float] = (
            (clock if callable(clock) else cpu_seconds_less_compiling) if mode == "cpu"
            else _zero)
        # A planner in this process is not charged for numba's compiler, nor is its thinking
        # time counted with it; one in a sandbox is charged what the kernel counts (its own
        # report is never trusted).
        self._compiler: Callable[[], tuple[float, float]] = (
            _zeros if self.external else compiler_spent)
        self.compiling_left_out_s = 0.0

    def read(self) -> ClockReading:
        """The clocks now, at the start of a call."""
        return ClockReading(self.cpu_seconds(), *self._compiler())

    def settle(self, wall_s: float, start: ClockReading) -> tuple[float, float]:
        """For a call that started at `start` and took `wall_s`: its thinking time (the wall
        time less numba's compiler) and the simulated seconds it is charged."""
        compiling_s, compiling_wall_s = self._compiler()
        self.compiling_left_out_s += compiling_s - start.compiling_s
        thinking_s = max(wall_s - (compiling_wall_s - start.compiling_wall_s), 0.0)
        return thinking_s, self.seconds(thinking_s, self.cpu_seconds() - start.cpu_s)

    def seconds(self, wall_s: float, cpu_s: float) -> float:
        """Simulated seconds charged for a call that took `wall_s` and used `cpu_s`."""
        if self.mode == "wall":
            return max(wall_s, 0.0)
        if self.mode == "cpu":
            return max(cpu_s, 0.0) * self.speed_factor
        return 0.0

    def describe(self) -> dict[str, Any]:
        """The charge as the result records it."""
        record: dict[str, Any] = {"mode": self.mode}
        if self.mode == "cpu":
            record["speed_factor"] = self.speed_factor
            record["clock"] = "sandbox" if self.external else "process"
        if self.mode != "none" and not self.external:
            record["compiling_left_out_s"] = self.compiling_left_out_s
        return record


def _zero() -> float:
    return 0.0


def _zeros() -> tuple[float, float]:
    return 0.0, 0.0
