"""What a planner's thinking costs on the simulated clock.

While a planner thinks, the simulated clock runs on (the vehicle hovers, or flies on along its
trajectory when asked mid-flight), as in a real-time system. The benchmark's presets charge the
CPU time the planner used for the call, counted by the runner and never reported by the planner:
for a planner in this process, the process's CPU time over the call (every thread); for one in
a sandbox, the sandbox's processes' CPU time as the kernel counts it (its `cpu_seconds()`).
The CPU time is scaled by the machine's speed factor (`sim.reference_speed`), so a charged
second is a second of the reference machine whatever the load or the machine.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any, Literal

ChargeMode = Literal["cpu", "wall", "none"]


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
            (clock if callable(clock) else time.process_time) if mode == "cpu" else _zero)

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
        return record


def _zero() -> float:
    return 0.0
