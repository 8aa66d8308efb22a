"""Does the API stay responsive while hostile planners are uploaded? `flybo serve` (API and one
idle worker, SQLite) in a fresh data folder; 20 users upload a hostile planner at once (each
kind in turn: one that spins at import, one that sleeps in every call, one that allocates
without end), while a client polls `/healthz` every 20 ms. Target: every `/healthz` answer within
100 ms. Reports the latency percentiles and how the uploads were answered (201 stored, 422
refused by the dry run, 429 over the limit of checks at once, others).

    .venv/bin/python benchmarks/healthz_under_uploads.py [--uploads 20] [--rounds 2]
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import httpx

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import create_token, free_port, print_table, service_env, wait_healthy, write_json

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


def _poll(base: str, stop: threading.Event, out: list[float], errors: list[str]) -> None:
    with httpx.Client(timeout=10) as client:
        while not stop.is_set():
            t0 = time.perf_counter()
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--uploads", type=int, default=20)
    parser.add_argument("--rounds", type=int, default=1, help="each hostile kind this often")
    args = parser.parse_args()
    rows, report = [], []
    with tempfile.TemporaryDirectory(prefix="flybo-bench-") as tmp:
        env = service_env(tmp)
        tokens = [create_token(env, f"user{i}") for i in range(args.uploads)]
        port = free_port()
        base = f"http://127.0.0.1:{port}"
        with open(Path(tmp) / "serve.log", "wb") as log:
            proc = subprocess.Popen([sys.executable, "-m", "flybo", "serve", "--port", str(port),
                                     "--no-viewer"], env=env, stdout=log,
                                    stderr=subprocess.STDOUT)
        try:
            wait_healthy(base)
            for round_ in range(args.rounds):
                for k, (kind, source) in enumerate(HOSTILE.items()):
                    latencies: list[float] = []
                    errors: list[str] = []
                    stop = threading.Event()
                    poller = threading.Thread(target=_poll, args=(base, stop, latencies, errors))
                    poller.start()
                    t0 = time.monotonic()
                    with ThreadPoolExecutor(args.uploads) as pool:
                        codes = list(pool.map(
                            lambda i, tag=f"hostile-{round_}-{k}", source=source: _upload(
                                base, tokens[i], f"{tag}-{i}", source),
                            range(args.uploads)))
                    took = time.monotonic() - t0
                    stop.set()
                    poller.join()
                    answered = Counter(codes)
                    p50, p99 = _percentile(latencies, 0.5), _percentile(latencies, 0.99)
                    worst = max(latencies)
                    rows.append([kind, str(len(latencies)), f"{p50:.1f}", f"{p99:.1f}",
                                 f"{worst:.1f}", str(len(errors)),
                                 " ".join(f"{c}:{n}" for c, n in sorted(answered.items())),
                                 f"{took:.1f}"])
                    report.append({"kind": kind, "round": round_, "polls": len(latencies),
                                   "p50_ms": p50, "p99_ms": p99, "max_ms": worst,
                                   "poll_errors": errors, "answers": dict(answered),
                                   "uploads_s": took, "mean_ms": statistics.fmean(latencies)})
        finally:
            proc.terminate()
            proc.wait(timeout=60)
    print_table(f"/healthz while {args.uploads} hostile uploads are checked at once",
                ["planner", "polls", "p50 ms", "p99 ms", "max ms", "poll errors",
                 "upload answers", "uploads s"], rows)
    met = all(r["max_ms"] <= 100.0 and not r["poll_errors"] for r in report)
    print(f"\ntarget: every /healthz answer within 100 ms: {'met' if met else 'NOT met'}")
    path = write_json("healthz_under_uploads", {"uploads": args.uploads, "rounds": args.rounds,
                                                "target_ms": 100.0, "met": met,
                                                "measurements": report})
    print(f"written {path}")


if __name__ == "__main__":
    main()
