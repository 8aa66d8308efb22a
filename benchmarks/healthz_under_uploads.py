"""Does the API stay responsive while hostile planners are uploaded? `flybo serve` (API and one
idle worker, SQLite) in a fresh data folder; 20 users upload a hostile planner at once (each
kind in turn: one that spins at import, one that sleeps in every call, one that allocates
without end), while a client polls `/healthz` every 20 ms, after polling it for 30 s with no
uploads (what the machine's load alone costs). Target: every `/healthz` answer within
100 ms. Reports the latency percentiles and how the uploads were answered (201 stored, 422
refused by the dry run, 429 over the limit of checks at once, others).

    .venv/bin/python benchmarks/healthz_under_uploads.py [--uploads 20] [--rounds 2] \
        [--watch-stalls]

With `--watch-stalls` the service notes every moment it stalled for more than 50 ms and which of
its threads were running then (`benchmarks/stall_watch.py`): a thread that holds the GIL shows
there; a stall with no thread running is the machine's load.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import httpx

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import create_token, free_port, print_table, service_env, wait_healthy, write_json
from stall_watch import summarize

HEADER = "import numpy as np\nfrom planners.api import Plan, Planner\n\n"
# Each stays within the upload's static checks and is stopped by a sandbox limit instead.
HOSTILE = {
    "spins at import": HEADER + (
        "class Spin(Planner):\n    def plan(self, obs):\n"
        "        return Plan(np.array([[*obs.pose.position, 0.0]]))\n\n\nwhile True:\n    pass\n"),
    "sleeps in every call": HEADER + (
        "import time\n\nclass Slow(Planner):\n    def plan(self, obs):\n"
        "        time.sleep(30)\n        return Plan(np.array([[*obs.pose.position, 0.0]]))\n"),
    "allocates without end": HEADER + (
        "class Greedy(Planner):\n    def plan(self, obs):\n        hoard = []\n"
        "        while True:\n            hoard.append(bytearray(64 * 1024 * 1024))\n"),
}


def _poll(base: str, stop: threading.Event, out: list[float], errors: list[str],
          at: list[float]) -> None:
    """Poll `/healthz` every 20 ms until `stop`: each answer's latency (ms) in `out` and when it
    was asked (perf_counter seconds) in `at`."""
    with httpx.Client(timeout=10) as client:
        while not stop.is_set():
            t0 = time.perf_counter()
            at.append(t0)
            try:
                status = client.get(f"{base}/healthz").status_code
                if status != 200:
                    errors.append(f"HTTP {status}")
            except httpx.HTTPError as exc:
                errors.append(type(exc).__name__)
            out.append((time.perf_counter() - t0) * 1000.0)
            time.sleep(0.02)


def _upload(base: str, token: str, name: str, source: str) -> int:
    response = httpx.post(f"{base}/api/v1/planners", headers={"Authorization": f"Bearer {token}"},
                          files={"file": ("planner.py", source.encode())},
                          data={"name": name}, timeout=300)
    return response.status_code


def _percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, round(q * (len(ordered) - 1)))]


def _burst(base: str, tokens: list[str], tag: str, source: str | None,
           stalls: Path | None, quiet_s: float = 0.0) -> dict[str, Any]:
    """20 (or `len(tokens)`) uploads of `source` at once while `/healthz` is polled; with no
    `source`, `quiet_s` seconds of polling alone (the machine's own share of the latency)."""
    latencies: list[float] = []
    asked: list[float] = []
    errors: list[str] = []
    stop = threading.Event()
    poller = threading.Thread(target=_poll, args=(base, stop, latencies, errors, asked))
    poller.start()
    time.sleep(0.2)  # a few answers before the burst
    load = os.getloadavg()[0]
    t0, burst, wall0 = time.monotonic(), time.perf_counter(), time.time()
    codes: list[int] = []
    if source is None:
        time.sleep(quiet_s)
    else:
        with ThreadPoolExecutor(len(tokens)) as pool:
            codes = list(pool.map(lambda i: _upload(base, tokens[i], f"{tag}-{i}", source),
                                  range(len(tokens))))
    took = time.monotonic() - t0
    stop.set()
    poller.join()
    # When the slowest answers were asked, in s since the burst began.
    slowest = sorted(zip(latencies, asked, strict=True), reverse=True)[:5]
    return {"polls": len(latencies), "p50_ms": _percentile(latencies, 0.5),
            "p99_ms": _percentile(latencies, 0.99), "max_ms": max(latencies),
            "poll_errors": errors, "answers": dict(Counter(codes)), "uploads_s": took,
            "mean_ms": statistics.fmean(latencies), "load_average": load,
            "slowest": [{"ms": ms, "asked_s": at - burst} for ms, at in slowest],
            "stalls": summarize(stalls, wall0, time.time()) if stalls else None}


def _serve_command(port: int, stalls: Path | None) -> list[str]:
    argv = ["serve", "--port", str(port), "--no-viewer"]
    if stalls is None:
        return [sys.executable, "-m", "flybo", *argv]
    here = str(Path(__file__).resolve().parent)
    return [sys.executable, "-c", f"import sys; sys.path.insert(0, {here!r}); import stall_watch; "
                                  f"stall_watch.serve({str(stalls)!r}, {argv!r})"]


def _row(kind: str, m: dict[str, Any]) -> list[str]:
    stalls = m["stalls"]
    seen = "" if stalls is None else (
        f"{stalls['stalls']} / {stalls['max_ms']:.0f} "
        + " ".join(f"{name}:{n}" for name, n in stalls["threads"].items()))
    return [kind, str(m["polls"]), f"{m['p50_ms']:.1f}", f"{m['p99_ms']:.1f}",
            f"{m['max_ms']:.1f}", str(len(m["poll_errors"])),
            " ".join(f"{c}:{n}" for c, n in sorted(m["answers"].items())),
            f"{m['uploads_s']:.1f}", f"{m['load_average']:.1f}", seen]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--uploads", type=int, default=20)
    parser.add_argument("--rounds", type=int, default=1, help="each hostile kind this often")
    parser.add_argument("--kinds", default=",".join(HOSTILE),
                        help="which hostile planners, comma-separated (default: all)")
    parser.add_argument("--server-log", type=Path,
                        help="keep the service's log here (it is deleted otherwise)")
    parser.add_argument("--quiet-s", type=float, default=30.0,
                        help="first poll this long with no uploads (0: not at all)")
    parser.add_argument("--watch-stalls", action="store_true",
                        help="note the service's stalls and the threads running in them "
                             "(benchmarks/stall_watch.py)")
    args = parser.parse_args()
    kinds = {kind: HOSTILE[kind] for kind in args.kinds.split(",")}
    rows, report = [], []
    with tempfile.TemporaryDirectory(prefix="flybo-bench-") as tmp:
        env = service_env(tmp)
        tokens = [create_token(env, f"user{i}") for i in range(args.uploads)]
        port = free_port()
        base = f"http://127.0.0.1:{port}"
        stalls = Path(tmp) / "stalls.jsonl" if args.watch_stalls else None
        with open(args.server_log or Path(tmp) / "serve.log", "wb") as log:
            proc = subprocess.Popen(_serve_command(port, stalls), env=env, stdout=log,
                                    stderr=subprocess.STDOUT)
        try:
            wait_healthy(base)
            if args.quiet_s > 0:
                measured = _burst(base, tokens, "", None, stalls, args.quiet_s)
                rows.append(_row("(no uploads)", measured))
                report.append({"kind": None, "round": None, **measured})
            for round_ in range(args.rounds):
                for k, (kind, source) in enumerate(kinds.items()):
                    measured = _burst(base, tokens, f"hostile-{round_}-{k}", source, stalls)
                    rows.append(_row(kind, measured))
                    report.append({"kind": kind, "round": round_, **measured})
        finally:
            proc.terminate()
            proc.wait(timeout=60)
    print_table(f"/healthz while {args.uploads} hostile uploads are checked at once",
                ["planner", "polls", "p50 ms", "p99 ms", "max ms", "poll errors",
                 "upload answers", "uploads s", "load avg", "stalls / max ms, threads"], rows)
    met = all(r["max_ms"] <= 100.0 and not r["poll_errors"] for r in report
              if r["kind"] is not None)
    print(f"\ntarget: every /healthz answer within 100 ms: {'met' if met else 'NOT met'}")
    path = write_json("healthz_under_uploads", {"uploads": args.uploads, "rounds": args.rounds,
                                                "target_ms": 100.0, "met": met,
                                                "measurements": report})
    print(f"written {path}")


if __name__ == "__main__":
    main()
