"""The worker processes `flybo serve --workers N` starts beside the API, and their stop.

Each is `flybo worker` in a process of its own, started with the thread limits in its
environment (`worker.threads`): its libraries read them as they load, before any run.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
import subprocess
import sys
import time
from collections.abc import Mapping, Sequence

from worker.threads import thread_environment, threads_per_worker

WORKER_COMMAND = (sys.executable, "-m", "flybo", "worker")


def worker_environment(workers: int, threads: int | None = None,
                       environ: Mapping[str, str] | None = None) -> dict[str, str]:
    """The environment of each of `workers` worker processes: `threads` threads each (default:
    the usable cores shared out, or `FLYBO_WORKER_THREADS`)."""
    env = os.environ if environ is None else environ
    return thread_environment(threads_per_worker(workers, threads, environ=env), env)


def start_workers(count: int, threads: int | None = None,
                  command: Sequence[str] = WORKER_COMMAND) -> list[subprocess.Popen[bytes]]:
    """Start `count` worker processes (`command`, `flybo worker` by default)."""
    env = worker_environment(count, threads)
    # Each worker leads its own process group (Celery's pool processes included), so that
    # stopping the service can stop all of them; and it is told to stop if the service dies.
    return [subprocess.Popen(list(command), env=env, start_new_session=True,
                             preexec_fn=_stop_with_parent)
            for _ in range(max(count, 0))]


def stop_workers(workers: Sequence[subprocess.Popen[bytes]], grace_s: float = 20.0) -> None:
    """SIGTERM to each worker, then, after `grace_s` for all, SIGKILL to what is left of their
    process groups."""
    for proc in workers:
        proc.send_signal(signal.SIGTERM)
    deadline = time.monotonic() + grace_s
    for proc in workers:
        with contextlib.suppress(subprocess.TimeoutExpired):
            proc.wait(timeout=max(deadline - time.monotonic(), 0.1))
        # A run still flying is given back to the queue (acks late) and flown again later.
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()


def _stop_with_parent() -> None:
    """In a worker before it starts: SIGTERM when the service process dies (Linux)."""
    pr_set_pdeathsig = 1
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None, use_errno=True).prctl(pr_set_pdeathsig, signal.SIGTERM)
