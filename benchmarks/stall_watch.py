"""Stalls of a Python process: a thread that sleeps 5 ms at a time notes each wake-up more than
50 ms late, with the threads of the process that were not waiting then (name and innermost
frame). A stall while another thread runs Python is that thread holding the GIL; a stall with
none is the process not getting a CPU (a loaded machine).

`benchmarks/healthz_under_uploads.py --watch-stalls` starts `flybo serve` through `serve`, and
`summarize` reads the log: the stalls, their total, and which threads ran during them.
"""

from __future__ import annotations

import json
import runpy
import sys
import threading
import time
from collections import Counter
from pathlib import Path
from typing import Any

# Innermost frames of a thread that waits (for a lock, a queue, a socket, the event loop).
WAITING = ("threading.py", "selectors.py", "queue.py", "socket.py", "ssl.py", "thread.py",
           "base_events.py", "stall_watch.py")


def _running(me: int) -> dict[str, str]:
    names = {thread.ident: thread.name for thread in threading.enumerate()}
    found = {}
    for ident, frame in sys._current_frames().items():
        code = frame.f_code
        if ident == me or code.co_filename.endswith(WAITING):
            continue
        name = names.get(ident, str(ident))
        found[name] = f"{Path(code.co_filename).name}:{frame.f_lineno} {code.co_name}"
    return found


def start(path: Path, *, period_s: float = 0.005, late_s: float = 0.05) -> threading.Thread:
    """Note this process's stalls in `path`, one JSON line each, from a daemon thread."""

    def watch() -> None:
        me = threading.get_ident()
        with path.open("a") as out:
            last = time.perf_counter()
            while True:
                time.sleep(period_s)
                now = time.perf_counter()
                late = now - last - period_s
                last = now
                if late > late_s:
                    out.write(json.dumps({"t": time.time(), "late_ms": late * 1000.0,
                                          "running": _running(me)}) + "\n")
                    out.flush()

    thread = threading.Thread(target=watch, name="stall-watch", daemon=True)
    thread.start()
    return thread


def serve(path: str, argv: list[str]) -> None:
    """`flybo ARGV...` in this process, its stalls noted in `path`."""
    start(Path(path))
    sys.argv = ["flybo", *argv]
    runpy.run_module("flybo", run_name="__main__", alter_sys=True)


def summarize(path: Path, since: float = 0.0, until: float = float("inf")) -> dict[str, Any]:
    """The stalls noted in `path` between `since` and `until` (time.time()): how many, their
    total and longest ms, and for each thread the stalls it was running in."""
    stalls = []
    if path.exists():
        for line in path.read_text().splitlines():
            stall = json.loads(line)
            if since <= stall["t"] <= until:
                stalls.append(stall)
    threads: Counter[str] = Counter()
    for stall in stalls:
        threads.update(name for name in stall["running"] if name != "MainThread")
    return {"stalls": len(stalls), "total_ms": sum(s["late_ms"] for s in stalls),
            "max_ms": max((s["late_ms"] for s in stalls), default=0.0),
            "threads": dict(threads.most_common(5)),
            "longest": sorted(stalls, key=lambda s: -s["late_ms"])[:3]}
