"""The machine's speed factor (`sim.reference_speed`), measured once per worker process.

It is measured in the background as the process starts (`measure_speed_in_background`, called
on Celery's `worker_process_init`), so that no run pays for it.
"""

from __future__ import annotations

import logging
import threading

log = logging.getLogger(__name__)

_speed_lock = threading.Lock()
_speed: list[float | None] = []  # empty until measured; [None] when measuring failed


def machine_speed_factor() -> float | None:
    """This machine's speed over the reference's (`sim.reference_speed.speed_factor`), measured
    on the first call of the process; a call meanwhile waits for it. None if it could not be
    measured (the episode then measures it itself, if its preset charges CPU time)."""
    with _speed_lock:
        if not _speed:
            try:
                from sim.reference_speed import speed_factor  # numba: in the run's process

                _speed.append(float(speed_factor()))
            except Exception as exc:
                log.warning("could not measure the machine's speed factor: %s", exc)
                _speed.append(None)
        return _speed[0]


def measure_speed_in_background() -> threading.Thread:
    """Start measuring the speed factor (about 2 s) in a thread of this process, so that a
    worker process is up at once and its first run finds the factor measured (or waits for
    the rest of the measurement)."""
    thread = threading.Thread(target=machine_speed_factor, name="speed-factor", daemon=True)
    thread.start()
    return thread
