"""A short job end to end on the embedded service: `flybo serve` (API + one worker, SQLite,
filesystem broker) in a fresh data folder, then MAZE + Classic, 2 runs of 60 simulated seconds.

Reports the time from start-up to a healthy API, and from submission to the job's end, beside
the target (under 2 minutes). Run: `.venv/bin/python benchmarks/service_job.py`.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import create_token, free_port, print_table, service_env, wait_healthy, write_json


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--runs", type=int, default=2)
    parser.add_argument("--seconds", type=float, default=60.0)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="flybo-bench-") as tmp:
        env = service_env(tmp)
        token = create_token(env, "bench")
        port = free_port()
        base = f"http://127.0.0.1:{port}"
        t0 = time.monotonic()
        with open(Path(tmp) / "serve.log", "wb") as log:
            proc = subprocess.Popen([sys.executable, "-m", "flybo", "serve", "--port", str(port)],
                                    env=env, stdout=log, stderr=subprocess.STDOUT)
        try:
            wait_healthy(base)
            startup = time.monotonic() - t0
            t1 = time.monotonic()
            job = httpx.post(f"{base}/api/v1/jobs", headers={"Authorization": f"Bearer {token}"},
                             json={"planner": "classic", "areas": ["maze"], "runs": args.runs,
                                   "seconds": args.seconds}, timeout=60).json()
            while job["status"] not in ("succeeded", "failed", "cancelled"):
                time.sleep(0.5)
                job = httpx.get(f"{base}/api/v1/jobs/{job['id']}", timeout=10).json()
            elapsed = time.monotonic() - t1
            runs = [httpx.get(f"{base}/api/v1/runs/{r['id']}").json() for r in job["runs"]]
        finally:
            proc.terminate()
            proc.wait(timeout=30)
    rows = [[f"run {r['id']} (seed {r['seed']})", r["status"], f"{r['wall_time_s']:.1f}",
             f"{r['result']['coverage']:.4f}" if r["result"] else "-"] for r in runs]
    print_table("runs", ["run", "status", "wall s (worker)", "coverage"], rows)
    print_table("short job on the embedded service",
                ["measure", "seconds", "target"],
                [["API start-up (migrations, catalog)", f"{startup:.1f}", "-"],
                 [f"job: {args.runs} x {args.seconds:g} s on MAZE, submit to end",
                  f"{elapsed:.1f}", "< 120"]])
    path = write_json("service_job", {"startup_s": startup, "job_s": elapsed,
                                      "status": job["status"], "runs": args.runs,
                                      "seconds": args.seconds, "target_s": 120,
                                      "run_wall_s": [r["wall_time_s"] for r in runs]})
    print(f"\nwritten {path}")


if __name__ == "__main__":
    main()
