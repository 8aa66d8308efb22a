"""200 clients polling a running job and the leaderboard, no think time, while a worker flies.

For each set-up, `flybo serve` in a fresh data folder (SQLite, the filesystem broker, one
worker) with 1 or N API processes (`--api-workers N`; more than one with Redis holding the
rate limits and the results epoch, `FLYBO_BENCH_REDIS_URL`). A job (MAZE + Classic, 2 runs of
700 simulated s) is submitted and, once its first run flies, `wrk -c200` drives the two URLs in
turn (`GET /api/v1/jobs/{id}` and `GET /api/v1/leaderboard`, each connection alternating, as
the load test's clients do) for `--seconds`. wrk sends `Accept-Encoding: gzip` as browsers and
HTTP libraries do. Everything shares the machine's two cores: the worker, the API processes and
wrk. The table lists requests/s, latency percentiles, errors (non-2xx/3xx and socket errors),
and how far the job got meanwhile.

`--before DIR` measures the code in DIR first (an unpacked `git archive` of an earlier commit):
its API, with one worker of this checkout beside it.

Run: `.venv/bin/python benchmarks/polling_load.py [--api-workers 1 2] [--seconds 60]
[--before DIR]`
(needs Debian's `wrk`: `make benchmark-system-deps`). Target: 0 errors and p99 at most 300 ms.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import (
    create_token,
    free_port,
    print_table,
    serve_command,
    service_env,
    wait_healthy,
    write_json,
)
from leaderboard_throughput import cpu_seconds, parse_wrk

CLIENTS = 200
TARGET_P99_MS = 300.0
REDIS_URL = os.environ.get("FLYBO_BENCH_REDIS_URL", "redis://127.0.0.1:6379/14")
# Each wrk connection alternates the two paths, starting with the job.
SCRIPT = """
local threads = {}
function setup(thread) table.insert(threads, thread) end
function init(args) n = 0; codes = {} end
local paths = {"/api/v1/jobs/%d", "/api/v1/leaderboard"}
function request()
  n = n + 1
  return wrk.format("GET", paths[(n %% 2) + 1])
end
function response(status, headers, body)
  codes[status] = (codes[status] or 0) + 1
end
function done(summary, latency, requests)
  local total = {}
  for _, t in ipairs(threads) do
    for status, count in pairs(t:get("codes")) do
      total[status] = (total[status] or 0) + count
    end
  end
  for status, count in pairs(total) do
    io.write(string.format("status %%d: %%d\\n", status, count))
  end
end
"""

def _running(base: str, job_id: int, timeout_s: float = 180.0) -> None:
    """Wait until a run of the job flies (its worker imported the stack and took it)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        runs = httpx.get(f"{base}/api/v1/jobs/{job_id}", timeout=10).json()["runs"]
        if any(r["status"] == "running" for r in runs):
            return
        time.sleep(0.5)
    raise SystemExit(f"no run of job {job_id} started within {timeout_s:g} s")


def _start(api_workers: int, env: dict[str, str], port: int, tmp: Path,
           tree: Path | None) -> list[subprocess.Popen[bytes]]:
    """`flybo serve` with one worker; for code before (`tree`), its API with this checkout's
    worker beside it on the same data folder (that code's worker command would import this
    checkout's installed package)."""
    flybo, cwd = serve_command(tree)
    options = ["--workers", "1", "--api-workers", str(api_workers)] if tree is None else \
        ["--workers", "0"]
    with (tmp / "serve.log").open("wb") as log:
        procs = [subprocess.Popen([*flybo, "serve", "--port", str(port), "--no-viewer",
                                   *options], env=env, stdout=log, stderr=subprocess.STDOUT,
                                  cwd=cwd)]
        if tree is not None:
            procs.append(subprocess.Popen([*serve_command()[0], "worker"], env=env,
                                          stdout=log, stderr=subprocess.STDOUT))
    return procs


def measure(api_workers: int, seconds: int, tmp: Path,
            tree: Path | None = None) -> dict[str, Any]:
    env = service_env(tmp / "data")
    if api_workers > 1:
        env["FLYBO_REDIS_URL"] = REDIS_URL
    token = create_token(env, "load")
    port = free_port()
    base = f"http://127.0.0.1:{port}"
    procs = _start(api_workers, env, port, tmp, tree)
    server = procs[0]
    try:
        wait_healthy(base)
        job = httpx.post(f"{base}/api/v1/jobs", headers={"Authorization": f"Bearer {token}"},
                         json={"planner": "classic", "areas": ["maze"], "runs": 2,
                               "seconds": 700}, timeout=120)
        job.raise_for_status()
        job_id = int(job.json()["id"])
        _running(base, job_id)
        script = tmp / "poll.lua"
        script.write_text(SCRIPT % job_id)
        before = httpx.get(f"{base}/api/v1/jobs/{job_id}", timeout=10).json()["progress"]
        load = os.getloadavg()[0]
        cpu = cpu_seconds(server.pid)
        done = subprocess.run(["wrk", f"-c{CLIENTS}", "-t2", f"-d{seconds}s", "--latency",
                               "--timeout", "10s", "-H", "Accept-Encoding: gzip", "-s",
                               str(script), base], capture_output=True, text=True, check=True)
        cpu = cpu_seconds(server.pid) - cpu
        after = httpx.get(f"{base}/api/v1/jobs/{job_id}", timeout=10).json()["progress"]
    finally:
        for proc in procs:
            proc.terminate()
        for proc in procs:
            try:
                proc.wait(timeout=60)
            except subprocess.TimeoutExpired:
                proc.kill()
    result = parse_wrk(done.stdout)
    statuses = {int(code): int(count) for code, count in
                re.findall(r"^status (\d+): (\d+)$", done.stdout, re.MULTILINE)}
    return {"code": "now" if tree is None else "before", "api_workers": api_workers, **result,
            "statuses": statuses, "loadavg_1min": load, "api_cpu_s": cpu,
            "job_progress": [before, after], "wrk": done.stdout}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--api-workers", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--seconds", type=int, default=60)
    parser.add_argument("--label", default="polling_load")
    parser.add_argument("--before", type=Path, default=None,
                        help="also measure the code in this folder first, one API process "
                             "(`git archive COMMIT | tar -x -C DIR`)")
    args = parser.parse_args()
    if shutil.which("wrk") is None:
        raise SystemExit("wrk is missing: `make benchmark-system-deps` installs it")
    rows = []
    if args.before is not None:
        with tempfile.TemporaryDirectory(prefix="flybo-bench-poll-") as tmp:
            rows.append(measure(1, args.seconds, Path(tmp), args.before))
    for count in args.api_workers:
        with tempfile.TemporaryDirectory(prefix="flybo-bench-poll-") as tmp:
            rows.append(measure(count, args.seconds, Path(tmp)))
    table = []
    for r in rows:
        errors = int(r["non_2xx"] + r["socket_errors"])
        met = errors == 0 and r["p99_ms"] <= TARGET_P99_MS
        codes = ", ".join(f"{k}: {v}" for k, v in sorted(r["statuses"].items()))
        table.append([r["code"], r["api_workers"], int(r["requests"]), codes, f"{r['rps']:.0f}",
                      f"{r['p50_ms']:.0f}", f"{r['p90_ms']:.0f}", f"{r['p99_ms']:.0f}", errors,
                      f"{1000 * r['api_cpu_s'] / max(r['requests'], 1):.2f}",
                      f"{r['job_progress'][0]:.2f} -> {r['job_progress'][1]:.2f}",
                      f"{r['loadavg_1min']:.1f}", "met" if met else "MISSED"])
    print_table(f"{CLIENTS} clients (wrk), job + leaderboard in turn, {args.seconds} s, one "
                "worker flying MAZE + Classic; SQLite, filesystem broker",
                ["code", "API processes", "requests", "statuses", "req/s", "p50 ms", "p90 ms",
                 "p99 ms", "errors", "API CPU ms/req", "job progress", "load",
                 f"0 errors, p99 <= {TARGET_P99_MS:.0f} ms"], table)
    path = write_json(args.label, {"clients": CLIENTS, "seconds": args.seconds,
                                   "target_p99_ms": TARGET_P99_MS, "results": rows})
    print(f"\nwrote {path}")


if __name__ == "__main__":
    main()
