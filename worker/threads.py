"""Threads per worker process: N workers on N cores, one thread each, so that they scale.

Open3D (rays, TSDF), numba and BLAS would each use every core of the machine in every worker
process; N workers then contend for the cores, and one run's spinning threads slow the others.
A worker process gets `max(1, usable cores // processes)` threads instead, `processes` being
every process that flies runs at once (`flybo serve --workers N`: N; `flybo worker
--concurrency C`: C). `--threads-per-worker` or `FLYBO_WORKER_THREADS` sets it explicitly.

- OpenMP, OpenBLAS, MKL and numba read their variables (`LIBRARY_VARIABLES`) once, when they are
  loaded: the launcher puts them into the environment of the process it starts
  (`thread_environment`), or `flybo worker` into its own before it imports any of them
  (`limit_this_process`). A variable the user set wins over the computed number.
- Open3D runs its CPU loops, ray casting included, on oneTBB, which reads no variable: the
  process that flies a run limits it with `open3d.utility.set_max_threads` to OMP_NUM_THREADS's
  value (`limit_open3d`), when the launcher marked the process (`THREADS_ENV` is set).
"""

from __future__ import annotations

import ctypes
import glob
import logging
import os
import sys
import threading
from collections.abc import Mapping
from pathlib import Path

log = logging.getLogger(__name__)

THREADS_ENV = "FLYBO_WORKER_THREADS"
LIBRARY_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                     "NUMBA_NUM_THREADS")
# Loaded before the limits were set, these keep the thread counts of the whole machine.
_READ_ON_LOAD = ("numpy", "numba", "open3d", "scipy")


class ThreadSettingError(ValueError):
    """An explicit thread count that is not a whole number of at least 1."""


def usable_cores() -> int:
    """The cores this process may run on (its affinity mask: taskset and cgroup cpusets)."""
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except (AttributeError, OSError):
        return max(os.cpu_count() or 1, 1)


def _whole(text: str, what: str) -> int:
    try:
        value = int(text.strip())
    except ValueError:
        raise ThreadSettingError(f"{what} must be a whole number, got {text!r}") from None
    if value < 1:
        raise ThreadSettingError(f"{what} must be at least 1, got {value}")
    return value


def threads_per_worker(processes: int, explicit: int | None = None, *,
                       environ: Mapping[str, str] | None = None,
                       cores: int | None = None) -> int:
    """Threads for each of `processes` processes flying runs at once on this machine: `explicit`,
    else `FLYBO_WORKER_THREADS`, else the usable cores shared out evenly (at least 1)."""
    if explicit is not None:
        return _whole(str(explicit), "--threads-per-worker")
    env = os.environ if environ is None else environ
    if env.get(THREADS_ENV, "").strip():
        return _whole(env[THREADS_ENV], THREADS_ENV)
    return max(1, (usable_cores() if cores is None else cores) // max(processes, 1))


def thread_environment(threads: int, environ: Mapping[str, str]) -> dict[str, str]:
    """`environ` with each library's thread variable at `threads`, unless the user set it."""
    env = dict(environ)
    for name in LIBRARY_VARIABLES:
        if not env.get(name, "").strip():
            env[name] = str(threads)
    env[THREADS_ENV] = str(threads)
    return env


def limit_this_process(threads: int) -> list[str]:
    """Set the limits in this process's own environment, for the libraries it has yet to load
    and for the pool processes it forks; returns the libraries already loaded, which keep
    their thread counts (nothing should have imported them yet)."""
    os.environ.update(thread_environment(threads, os.environ))
    loaded = [name for name in _READ_ON_LOAD if name in sys.modules]
    if loaded:
        log.warning("thread limits set after %s loaded: those keep their own thread counts",
                    ", ".join(loaded))
    return loaded


def _open3d_threads(environ: Mapping[str, str]) -> int | None:
    """Open3D's limit: OMP_NUM_THREADS's (its first number, as OpenMP reads "4,2"), else the
    worker's threads; None in a process no launcher limited."""
    if not environ.get(THREADS_ENV, "").strip():
        return None
    for text in (environ.get("OMP_NUM_THREADS", "").split(",")[0], environ[THREADS_ENV]):
        try:
            return max(int(text.strip()), 1)
        except ValueError:
            continue
    return None


_open3d_lock = threading.Lock()
_open3d_applied: list[int | None] = []


def limit_open3d() -> int | None:
    """Limit Open3D's threads in this process, once (the first call imports Open3D); the limit,
    or None when this process was not started as a limited worker."""
    with _open3d_lock:
        if not _open3d_applied:
            threads = _open3d_threads(os.environ)
            if threads is not None:
                import open3d  # the simulation stack: in the process that flies runs

                open3d.utility.set_max_threads(threads)
            _open3d_applied.append(threads)
        return _open3d_applied[0]


def blas_threads() -> int | None:
    """The threads numpy's bundled OpenBLAS uses, asked from the library itself; None when
    numpy has no bundled OpenBLAS (another BLAS, or numpy not loaded)."""
    numpy = sys.modules.get("numpy")
    if numpy is None or numpy.__file__ is None:
        return None
    folder = Path(numpy.__file__).parent.parent / "numpy.libs"
    for path in sorted(glob.glob(str(folder / "lib*openblas*.so*"))):
        lib = ctypes.CDLL(path)  # already loaded by numpy: the same library, not a second copy
        for symbol in ("scipy_openblas_get_num_threads64_", "openblas_get_num_threads64_",
                       "openblas_get_num_threads"):
            if hasattr(lib, symbol):
                return int(getattr(lib, symbol)())
    return None


def thread_report() -> str:
    """What limits this process's threads, for the run's log."""
    parts = [f"{name} {os.environ.get(name, 'unset')}" for name in LIBRARY_VARIABLES]
    if "open3d" in sys.modules:
        parts.append(f"Open3D {sys.modules['open3d'].utility.get_max_threads()}")
    if "numba" in sys.modules:
        parts.append(f"numba {sys.modules['numba'].config.NUMBA_NUM_THREADS}")
    blas = blas_threads()
    if blas is not None:
        parts.append(f"OpenBLAS {blas}")
    return "threads: " + ", ".join(parts)
