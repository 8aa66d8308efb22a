"""The machine's speed against a reference, so that planning time is charged in reference seconds.

A planner's CPU time per `plan` call depends on the machine. Each process that runs episodes
measures a fixed, short, single-threaded workload of the kinds planners spend their time in
(numba loops over voxel grids and NumPy array work) once, and the charge of a call is its CPU
time times the factor `REFERENCE_CPU_S / measured`: on a machine twice as slow the factor is
0.5, so a run is not penalised for where it ran. The workload's time is read as the CPU time
of the measuring thread, which other processes on the machine barely move; the least of a few
repetitions is kept. `benchmarks/load_independence.py` reports its spread.
"""

from __future__ import annotations

import functools
import time

import numba
import numpy as np
import numpy.typing as npt

# The workload's CPU time on the reference machine (a 2-core x86-64 cloud machine, Python 3.11),
# `python -c "from sim.reference_speed import measure_cpu_s; print(measure_cpu_s())"`. Fixed: it
# is part of the benchmark version, as it sets what a charged second means.
REFERENCE_CPU_S = 0.080
REPETITIONS = 15


@numba.njit(cache=True)
def _walk(grid: npt.NDArray[np.uint8], steps: int) -> int:  # pragma: no cover - numba
    """A pseudo-random walk through a voxel grid, counting what it meets: memory-bound integer
    work like ray traversal and path search."""
    nx, ny, nz = grid.shape
    x, y, z = nx // 2, ny // 2, nz // 2
    state = np.uint32(12345)
    seen = 0
    for _ in range(steps):
        state = state * np.uint32(1664525) + np.uint32(1013904223)
        move = (state >> np.uint32(16)) % np.uint32(6)
        if move == 0:
            x = (x + 1) % nx
        elif move == 1:
            x = (x - 1) % nx
        elif move == 2:
            y = (y + 1) % ny
        elif move == 3:
            y = (y - 1) % ny
        elif move == 4:
            z = (z + 1) % nz
        else:
            z = (z - 1) % nz
        seen += grid[x, y, z]
    return seen


def _workload(grid: npt.NDArray[np.uint8], points: npt.NDArray[np.float64]) -> float:
    walked = _walk(grid, 2_000_000)
    # Array work without BLAS (whose threads would make it multi-threaded).
    order = np.argsort(points[:, 0], kind="stable")
    dist = np.sqrt(np.sum(np.square(points[order] - points[0]), axis=1))
    return float(walked) + float(np.count_nonzero(dist < 0.5))


def measure_cpu_s(repetitions: int = REPETITIONS) -> float:
    """The least CPU time of the calling thread over `repetitions` runs of the workload, s."""
    rng = np.random.default_rng(0)
    grid = (rng.random((96, 96, 48)) < 0.3).astype(np.uint8)
    points = rng.random((200_000, 3))
    _walk(grid, 10)  # compiled (or loaded from numba's cache) outside the timing
    best = float("inf")
    for _ in range(repetitions):
        t0 = time.thread_time()
        _workload(grid, points)
        best = min(best, time.thread_time() - t0)
    return best


@functools.cache
def speed_factor() -> float:
    """This machine's speed over the reference's (1.0 on the reference machine, 0.5 on one twice
    as slow), measured once per process."""
    return REFERENCE_CPU_S / measure_cpu_s()
