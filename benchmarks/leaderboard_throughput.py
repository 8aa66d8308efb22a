"""Throughput of `GET /api/v1/leaderboard` on SQLite and PostgreSQL, measured with `wrk`.

LOAD FIXTURE: the same synthetic results as `benchmarks/leaderboard_page.py` (7 planners x
11 areas x 5 runs with results and curves, written through the ORM; no simulation runs). The
API is started as `flybo serve --workers 0 --no-viewer` starts it (uvicorn with the same
settings, one process), first on a SQLite file and then on a fresh PostgreSQL database. After a
warm-up, `wrk -t2 -d20s --latency` drives the whole leaderboard and the one of `?area=warehouse`
at 1, 8 and 32 connections; the table lists requests/s, the p50/p90/p99 latencies and the
server's CPU time per request (from /proc: what the server costs whatever else runs).

The machine has two cores: the server is pinned to one (`taskset -c 0`) and wrk to the other
(`taskset -c 1`), so the client does not take the server's core. Other work on the machine
still competes for both; the load average is recorded beside each measurement.

`--api-workers 1 2` measures each number of API processes side by side (`flybo serve
--api-workers N`; with more than one, Redis holds what they share, `FLYBO_BENCH_REDIS_URL`).
One process is pinned to CPU 0 as above; N processes run unpinned on both cores, wrk with them
(the machine has no third core to give it), and the CPU per request sums all of them.

Run: `.venv/bin/python benchmarks/leaderboard_throughput.py [--duration 20] [--only sqlite]
[--api-workers 1 2] [--connections 32]` (needs Debian's `wrk`: `make benchmark-system-deps`).
PostgreSQL: `FLYBO_BENCH_POSTGRES_URL` (default `postgresql+psycopg://postgres@127.0.0.1:5432/
test`, used to create and drop the fresh database). Targets at 32 connections: at least 2,000
requests/s with p99 under 50 ms (before: 500 requests/s, p99 under 100 ms).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import httpx

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import print_table, serve_command, write_json
from leaderboard_page import AREAS, PLANNERS, RUNS, _port, _wait_synced, fill_load_fixture

POSTGRES_ADMIN_URL = os.environ.get("FLYBO_BENCH_POSTGRES_URL",
                                    "postgresql+psycopg://postgres@127.0.0.1:5432/test")
REDIS_URL = os.environ.get("FLYBO_BENCH_REDIS_URL", "redis://127.0.0.1:6379/14")
CONNECTIONS = (1, 8, 32)
TARGET_RPS = 2000.0
TARGET_P99_MS = 50.0
SERVER_CPU = "0"
CLIENT_CPU = "1"
_UNITS_MS = {"us": 1e-3, "ms": 1.0, "s": 1000.0, "m": 60_000.0}


def parse_wrk(text: str) -> dict[str, float]:
    """Requests/s, p50/p90/p99 latency (ms), request count and errors from `wrk --latency`."""
    out: dict[str, float] = {}
    rps = re.search(r"Requests/sec:\s+([\d.]+)", text)
    if rps is None:
        raise ValueError(f"no Requests/sec in wrk output:\n{text}")
    out["rps"] = float(rps.group(1))
    for pct in ("50", "90", "99"):
        found = re.search(rf"^\s+{pct}(?:\.0+)?%\s+([\d.]+)(us|ms|s|m)\s*$", text, re.MULTILINE)
        if found is None:
            raise ValueError(f"no {pct}% latency in wrk output:\n{text}")
        out[f"p{pct}_ms"] = float(found.group(1)) * _UNITS_MS[found.group(2)]
    total = re.search(r"(\d+) requests in", text)
    out["requests"] = float(total.group(1)) if total else 0.0
    non2xx = re.search(r"Non-2xx or 3xx responses:\s+(\d+)", text)
    out["non_2xx"] = float(non2xx.group(1)) if non2xx else 0.0
    socket = re.search(r"Socket errors: connect (\d+), read (\d+), write (\d+), timeout (\d+)",
                       text)
    out["socket_errors"] = float(sum(int(g) for g in socket.groups())) if socket else 0.0
    return out


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process and its children alive now (the API processes of
    `--api-workers N`) so far (Linux /proc)."""
    total = 0.0
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(entry.name) == pid or int(fields[1]) == pid:
            total += (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    return total


def run_wrk(url: str, connections: int, duration_s: int, server_pid: int,
            pinned: bool = True) -> dict[str, float]:
    """One wrk run; also the server's CPU seconds per 1000 requests, which the other work on
    the machine does not change (unlike requests/s)."""
    threads = min(2, connections)
    cmd = [*(["taskset", "-c", CLIENT_CPU] if pinned else []), "wrk", f"-c{connections}",
           f"-t{threads}", f"-d{duration_s}s", "--latency", url]
    load = os.getloadavg()[0]
    cpu = cpu_seconds(server_pid)
    done = subprocess.run(cmd, capture_output=True, text=True, check=True)
    cpu = cpu_seconds(server_pid) - cpu
    result = parse_wrk(done.stdout)
    result["loadavg_1min"] = load
    result["server_cpu_s"] = cpu
    result["server_cpu_ms_per_request"] = 1000.0 * cpu / max(result["requests"], 1.0)
    return result


@contextmanager
def postgres_database() -> Iterator[str]:
    """A fresh PostgreSQL database, dropped afterwards."""
    from sqlalchemy import create_engine, text

    name = f"flybo_bench_{uuid.uuid4().hex[:10]}"
    admin = create_engine(POSTGRES_ADMIN_URL, isolation_level="AUTOCOMMIT")
    with admin.connect() as conn:
        conn.execute(text(f'CREATE DATABASE "{name}"'))
    try:
        yield admin.url.set(database=name).render_as_string(hide_password=False)
    finally:
        with admin.connect() as conn:
            conn.execute(text("SELECT pg_terminate_backend(pid) FROM pg_stat_activity "
                              f"WHERE datname = '{name}'"))
            conn.execute(text(f'DROP DATABASE IF EXISTS "{name}"'))
        admin.dispose()


@contextmanager
def serving(tmp: Path, database_url: str | None, nice: int = 0,
            api_workers: int = 1, tree: Path | None = None) -> Iterator[tuple[str, int]]:
    """`flybo serve` on one pinned core (or `api_workers` processes on all); yields its base
    URL and process id once the areas are synced."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("FLYBO_")}
    env["FLYBO_DATA_DIR"] = str(tmp)
    if "FLYBO_CACHE_DIR" in os.environ:
        env["FLYBO_CACHE_DIR"] = os.environ["FLYBO_CACHE_DIR"]
    if database_url is not None:
        env["FLYBO_DATABASE_URL"] = database_url
    if api_workers > 1:
        env["FLYBO_REDIS_URL"] = REDIS_URL
    pin = ["taskset", "-c", SERVER_CPU] if api_workers == 1 else []
    port = _port()
    base = f"http://127.0.0.1:{port}"
    with open(tmp / "serve.log", "wb") as log:
        # taskset and nice exec what they run: the process id stays the server's.
        priority = ["nice", "-n", str(nice)] if nice else []
        flybo, cwd = serve_command(tree)
        # The code before had one API process and no --api-workers option.
        processes = [] if tree is not None else ["--api-workers", str(api_workers)]
        proc = subprocess.Popen([*priority, *pin, *flybo, "serve", "--port", str(port),
                                 "--workers", "0", "--no-viewer", *processes],
                                env=env, stdout=log, stderr=subprocess.STDOUT, cwd=cwd)
    try:
        deadline = time.monotonic() + 120
        while True:
            if proc.poll() is not None:
                tail = (tmp / "serve.log").read_text(errors="replace")[-3000:]
                raise RuntimeError(f"the server exited:\n{tail}")
            try:
                if httpx.get(f"{base}/healthz", timeout=2).status_code == 200:
                    break
            except httpx.HTTPError:
                pass
            if time.monotonic() > deadline:
                raise RuntimeError("the server did not answer /healthz within 120 s")
            time.sleep(0.2)
        _wait_synced(base)
        yield base, proc.pid
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()


def measure(served: tuple[str, int], duration_s: int, warmup_s: int,
            connections: tuple[int, ...], api_workers: int) -> list[dict[str, Any]]:
    base, pid = served
    rows: list[dict[str, Any]] = []
    for query in ("", "?area=warehouse"):
        url = f"{base}/api/v1/leaderboard{query}"
        board = httpx.get(url, timeout=30)
        board.raise_for_status()
        entries = len(board.json()["entries"])
        pinned = api_workers == 1
        run_wrk(url, 32, warmup_s, pid, pinned)  # warm-up: caches, pools, connections
        for count in connections:
            result = run_wrk(url, count, duration_s, pid, pinned)
            rows.append({"query": query or "(all areas)", "connections": count,
                         "api_workers": api_workers, "entries": entries,
                         "bytes": len(board.content), **result})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--duration", type=int, default=20, help="seconds per wrk run")
    parser.add_argument("--warmup", type=int, default=5, help="seconds of warm-up per URL")
    parser.add_argument("--only", choices=("sqlite", "postgresql"), default=None)
    parser.add_argument("--nice", type=int, default=0,
                        help="diagnostic only: run the server at this niceness (negative: "
                             "ahead of other work on its core; needs root)")
    parser.add_argument("--label", default="leaderboard_throughput",
                        help="name of the JSON file under benchmarks/results")
    parser.add_argument("--api-workers", type=int, nargs="+", default=[1],
                        help="numbers of API processes to measure, in turn (default 1)")
    parser.add_argument("--connections", type=int, nargs="+", default=list(CONNECTIONS))
    parser.add_argument("--before", type=Path, default=None,
                        help="also measure the code in this folder first, one API process "
                             "(`git archive COMMIT | tar -x -C DIR`)")
    args = parser.parse_args()
    if shutil.which("wrk") is None:
        raise SystemExit("wrk is missing: `make benchmark-system-deps` installs it")
    if (os.cpu_count() or 1) < 2:
        raise SystemExit("two cores are needed: one for the server, one for wrk")
    results: dict[str, list[dict[str, Any]]] = {}
    for backend in ("sqlite", "postgresql"):
        if args.only not in (None, backend):
            continue
        results[backend] = _backend(backend, args)
    table = []
    for backend, rows in results.items():
        for r in rows:
            met = (r["rps"] >= TARGET_RPS and r["p99_ms"] < TARGET_P99_MS
                   if r["connections"] == 32 else None)
            errors = int(r["non_2xx"] + r["socket_errors"])
            table.append([backend, r["code"], r["api_workers"], r["query"], r["connections"],
                          f"{r['rps']:.0f}", f"{r['p50_ms']:.1f}", f"{r['p90_ms']:.1f}",
                          f"{r['p99_ms']:.1f}", errors, f"{r['server_cpu_ms_per_request']:.2f}",
                          f"{r['loadavg_1min']:.1f}",
                          "" if met is None else ("met" if met else "MISSED")])
    print_table(
        f"GET /api/v1/leaderboard, {PLANNERS} planners x {len(AREAS)} areas x {RUNS} runs; "
        f"one API process pinned to CPU {SERVER_CPU} and wrk -t2 -d{args.duration}s to CPU "
        f"{CLIENT_CPU}, or N API processes and wrk on both"
        + (f"; server niceness {args.nice}" if args.nice else ""),
        ["database", "code", "API processes", "query", "conns", "req/s", "p50 ms", "p90 ms",
         "p99 ms", "errors", "server CPU ms/req", "load",
         f">= {TARGET_RPS:.0f}/s, p99 < {TARGET_P99_MS:.0f} ms"],
        table)
    path = write_json(args.label, {
        "planners": PLANNERS, "areas": len(AREAS), "runs_per_area": RUNS,
        "server_cpu": SERVER_CPU, "client_cpu": CLIENT_CPU, "duration_s": args.duration,
        "server_niceness": args.nice, "target_rps": TARGET_RPS, "target_p99_ms": TARGET_P99_MS,
        "api_workers": args.api_workers, "results": results})
    print(f"\nwrote {path}")


def _backend(backend: str, args: argparse.Namespace) -> list[dict[str, Any]]:
    """Every set-up of `args.api_workers` on one fresh database of `backend`."""
    rows: list[dict[str, Any]] = []
    connections = tuple(args.connections)
    with tempfile.TemporaryDirectory(prefix="flybo-bench-lb-") as tmp_name:
        tmp = Path(tmp_name)
        with contextlib.ExitStack() as stack:
            if backend == "sqlite":
                url = None
                fill_load_fixture(f"sqlite:///{tmp / 'flybo.sqlite'}")
            else:
                url = stack.enter_context(postgres_database())
                fill_load_fixture(url)
            if args.before is not None:
                with serving(tmp, url, args.nice, 1, args.before) as served:
                    rows += [{**row, "code": "before"} for row in
                             measure(served, args.duration, args.warmup, connections, 1)]
            for count in args.api_workers:
                with serving(tmp, url, args.nice, count) as served:
                    rows += [{**row, "code": "now"} for row in
                             measure(served, args.duration, args.warmup, connections, count)]
    return rows


if __name__ == "__main__":
    main()
