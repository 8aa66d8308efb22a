"""The process's CPU time less the time numba spent compiling kernels or loading them.

A numba kernel is compiled the first time it is called with new argument types, or loaded from
numba's on-disk cache if the cache holds it. Which of the two happens depends on the
installation, not on the method: on a fresh install the first run of a planner was charged
seconds of compilation in one planning call (7.3 s for Classic's first call on MAZE against
0.06 s with the cache filled) and flew another run. So the in-process planning charge reads
this clock, which leaves out the CPU time spent holding numba's compiler lock (events of kind
"numba:compiler_lock", `numba.core.event`): compiling, and loading and saving cached code. A
kernel that calls others takes the lock again inside; only the outermost hold is timed. The
process's CPU time is read, so another thread's work during a hold is left out with it.

A planner in a sandbox is charged by the kernel's count of its processes' CPU time: nothing it
reports is trusted, so compilation there is charged; the sandbox starts with the worker's
compiled kernels (`worker.sandbox.packages.seed_numba_cache`).
"""

from __future__ import annotations

import threading
import time

from numba.core import event

__all__ = ["compiler_spent", "compiling_seconds", "compiling_wall_seconds",
           "cpu_seconds_less_compiling"]


class _CompileTimer(event.Listener):
    """Process CPU time and wall time spent in outermost holds of numba's compiler lock."""

    def __init__(self) -> None:
        self.total = 0.0
        self.total_wall = 0.0
        self._depth = 0
        self._started = 0.0
        self._started_wall = 0.0
        # The compiler lock lets one thread in at a time, but its events start before it is
        # taken: another thread's start may arrive while one holds it.
        self._lock = threading.Lock()

    def on_start(self, event: event.Event) -> None:
        with self._lock:
            if self._depth == 0:
                self._started = time.process_time()
                self._started_wall = time.perf_counter()
            self._depth += 1

    def on_end(self, event: event.Event) -> None:
        with self._lock:
            self._depth -= 1
            if self._depth == 0:
                self.total += time.process_time() - self._started
                self.total_wall += time.perf_counter() - self._started_wall

    def spent(self) -> tuple[float, float]:
        """CPU and wall seconds in the compiler so far, the hold under way included."""
        with self._lock:
            if not self._depth:
                return self.total, self.total_wall
            return (self.total + time.process_time() - self._started,
                    self.total_wall + time.perf_counter() - self._started_wall)


_TIMER = _CompileTimer()
event.register("numba:compiler_lock", _TIMER)


def compiler_spent() -> tuple[float, float]:
    """CPU and wall seconds this process has spent in numba's compiler."""
    return _TIMER.spent()


def compiling_seconds() -> float:
    """CPU seconds this process has spent in numba's compiler (compiling, loading cached
    code)."""
    return _TIMER.spent()[0]


def compiling_wall_seconds() -> float:
    """Wall seconds this process has spent in numba's compiler."""
    return _TIMER.spent()[1]


def cpu_seconds_less_compiling() -> float:
    """The process's CPU time (every thread) less `compiling_seconds()`."""
    return time.process_time() - _TIMER.spent()[0]
