"""Runs loaded once and shared by every tab that watches them."""

from __future__ import annotations

import logging
import threading
from collections import OrderedDict
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor

from web.replay.extras import Extras, compute_extras
from web.replay.source import RunData

log = logging.getLogger(__name__)

# A loaded 1800 s run holds its recording and map checkpoints: tens of MB. A few stay loaded.
DEFAULT_CAPACITY = 4


class RunCache:
    """Least-recently-used runs by key; a run asked for by two tabs at once is loaded once."""

    def __init__(self, loader: Callable[[str], RunData],
                 capacity: int = DEFAULT_CAPACITY) -> None:
        self._loader = loader
        self._capacity = max(1, capacity)
        self._lock = threading.Lock()
        self._runs: OrderedDict[str, RunData] = OrderedDict()
        self._extras: dict[str, Future[Extras]] = {}
        self._key_locks: dict[str, threading.Lock] = {}
        # One worker: the extras are CPU-heavy and the machine may have two cores.
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="replay-extras")

    def get(self, key: str) -> RunData:
        """The run under `key`, loading it on first use (exceptions of the loader propagate)."""
        with self._lock:
            key_lock = self._key_locks.setdefault(key, threading.Lock())
        with key_lock:
            with self._lock:
                run = self._runs.get(key)
                if run is not None:
                    self._runs.move_to_end(key)
                    return run
            run = self._loader(key)
            with self._lock:
                self._runs[key] = run
                self._extras[key] = self._submit(run)
                while len(self._runs) > self._capacity:
                    old, _ = self._runs.popitem(last=False)
                    self._extras.pop(old, None)
            return run

    def extras(self, run: RunData) -> Future[Extras]:
        """The background computation of the run's truth cloud and coloured final mesh."""
        with self._lock:
            future = self._extras.get(run.key)
            if future is None:  # evicted meanwhile: compute again for this tab
                future = self._extras[run.key] = self._submit(run)
            return future

    def _submit(self, run: RunData) -> Future[Extras]:
        future = self._pool.submit(compute_extras, run)

        def report(done: Future[Extras]) -> None:
            if not done.cancelled() and done.exception() is not None:
                # Tabs simply go without the truth cloud and the final mesh.
                log.error("background work for %s failed: %s", run.key, done.exception())

        future.add_done_callback(report)
        return future

    def close(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)
