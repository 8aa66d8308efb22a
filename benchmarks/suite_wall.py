"""Wall time of one planner's suite on the embedded service, with 1 and with 2 workers.

For each worker count: `flybo serve --workers N` in a fresh data folder (SQLite, filesystem
broker), wait until the API has synced every built-in area (that build would otherwise compete
with the runs), submit the suite as one job group (`POST /api/v1/groups`: the planner on the
areas, R runs each, each run lasting `--time-scale` x the area's plateau time, the duration the
service gives a run by default), and wait for it. Reports the wall time from submission to the
group's end, the simulated seconds, simulated seconds per wall second, the speed-up over one
worker, the CPU seconds the workers and the API process used meanwhile (how many cores the
workers kept busy, and their CPU per simulated second: what a run costs), and what the rate
means for the full suite (11 areas x 5 runs at the plateau times: 56,250 simulated s) beside
the paper's 17 h 30 min.

Run (a small subset; the full suite takes hours):
    .venv/bin/python benchmarks/suite_wall.py --areas maze offices-a --runs 1 --time-scale 0.1
"""

from __future__ import annotations

import argparse
import os
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import print_table, write_json

PAPER_SUITE_WALL_S = 17.5 * 3600  # "in merely 17h30 of computation" (the paper's conclusion)
PAPER_RUNS = 5  # runs per area in the paper's tables
FINAL = {"succeeded", "failed", "cancelled"}


def _port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _env(data: Path) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("FLYBO_")}
    env["FLYBO_DATA_DIR"] = str(data)
    if "FLYBO_CACHE_DIR" in os.environ:  # the area cache (ground truth) is shared on purpose
        env["FLYBO_CACHE_DIR"] = os.environ["FLYBO_CACHE_DIR"]
    return env


def _wait(what: str, check: Any, timeout: float, log: Path) -> float:
    began = time.monotonic()
    while not check():
        if time.monotonic() - began > timeout:
            raise SystemExit(f"{what} took over {timeout:.0f} s; log:\n"
                             f"{log.read_text(errors='replace')[-3000:]}")
        time.sleep(0.5)
    return time.monotonic() - began


def _cpu_s(pid: int) -> dict[str, float]:
    """CPU seconds (user + system, all threads) used so far by process `pid` ("api") and by
    all its descendants ("workers": the worker processes and their pool children), from /proc.
    A process that exits between two readings takes its seconds with it, so read while the
    tree is alive."""
    tick = os.sysconf("SC_CLK_TCK")
    parent: dict[int, int] = {}
    used: dict[int, float] = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            # The command name may hold spaces and parentheses: split after its closing one.
            fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
        except (OSError, IndexError):
            continue
        parent[int(entry.name)] = int(fields[1])
        used[int(entry.name)] = (int(fields[11]) + int(fields[12])) / tick
    tree, frontier = set(), [pid]
    while frontier:
        children = [p for p, pp in parent.items() if pp in frontier and p not in tree]
        tree.update(children)
        frontier = children
    return {"api": used.get(pid, 0.0), "workers": sum(used[p] for p in tree)}


def _healthy(base: str) -> bool:
    try:
        return httpx.get(f"{base}/healthz", timeout=2).status_code == 200
    except httpx.HTTPError:
        return False


def measure(workers: int, args: argparse.Namespace, builtin_areas: list[str]) -> dict[str, Any]:
    """One suite on a fresh `flybo serve --workers N`; the numbers of `main`'s table."""
    with tempfile.TemporaryDirectory(prefix="flybo-suite-") as tmp:
        data = Path(tmp) / "data"
        env = _env(data)
        token = subprocess.run([sys.executable, "-m", "flybo", "tokens", "create", "--user",
                                "bench", "--admin"], env=env, check=True, capture_output=True,
                               text=True).stdout.strip()
        port = _port()
        base = f"http://127.0.0.1:{port}"
        log = Path(tmp) / "serve.log"
        with log.open("wb") as out:
            proc = subprocess.Popen([sys.executable, "-m", "flybo", "serve", "--port", str(port),
                                     "--workers", str(workers), "--no-viewer"], env=env,
                                    stdout=out, stderr=subprocess.STDOUT)
        try:
            startup = _wait("API start-up", lambda: _healthy(base), 180, log)
            synced = _wait("area sync", lambda: len(httpx.get(
                f"{base}/api/v1/areas", timeout=30).json()) >= len(builtin_areas), 900, log)
            plateau = {a["name"]: a["plateau_s"]
                       for a in httpx.get(f"{base}/api/v1/areas", timeout=30).json()}
            began = time.monotonic()
            cpu_began = _cpu_s(proc.pid)
            response = httpx.post(f"{base}/api/v1/groups", timeout=120,
                                  headers={"Authorization": f"Bearer {token}"},
                                  json={"planners": [args.planner], "areas": args.areas,
                                        "runs": args.runs, "preset": args.preset,
                                        "time_scale": args.time_scale,
                                        "name": f"suite-wall {workers} worker(s)"})
            if response.status_code != 201:
                raise SystemExit(f"POST /groups answered {response.status_code}: "
                                 f"{response.text}")
            group = response.json()
            while group["status"] not in FINAL:
                time.sleep(1.0)
                group = httpx.get(f"{base}/api/v1/groups/{group['id']}", timeout=30).json()
            wall = time.monotonic() - began
            cpu_ended = _cpu_s(proc.pid)
            runs = []
            for planner in group["planners"]:
                for job_id in planner["jobs"]:
                    job = httpx.get(f"{base}/api/v1/jobs/{job_id}", timeout=30).json()
                    runs += [httpx.get(f"{base}/api/v1/runs/{r['id']}", timeout=30).json()
                             for r in job["runs"]]
        finally:
            proc.terminate()
            try:
                proc.wait(timeout=60)
            except subprocess.TimeoutExpired:
                proc.kill()
    simulated = sum(r["result"]["simulated_until_s"] for r in runs if r["result"])
    cpu = {k: cpu_ended[k] - cpu_began[k] for k in cpu_began}
    return {
        "plateau_s": plateau, "workers": workers, "status": group["status"],
        "by_status": group["by_status"],
        "startup_s": round(startup, 1), "area_sync_s": round(synced, 1),
        "wall_s": round(wall, 1), "simulated_s": round(simulated, 1),
        "sim_per_wall": simulated / wall if wall > 0 else 0.0,
        "worker_cpu_s": round(cpu["workers"], 1), "api_cpu_s": round(cpu["api"], 1),
        "worker_cores_busy": cpu["workers"] / wall if wall > 0 else 0.0,
        "worker_cpu_per_sim_s": cpu["workers"] / simulated if simulated > 0 else 0.0,
        "run_wall_s": [round(r["wall_time_s"] or 0.0, 1) for r in runs],
        "runs": [{"area": r["area"], "seed": r["seed"], "seconds": r["seconds"],
                  "status": r["status"], "wall_s": r["wall_time_s"],
                  "worker": r["worker"]} for r in runs],
    }


def _hours(seconds: float) -> str:
    return f"{int(seconds // 3600)} h {int(seconds % 3600 // 60):02d} min"


def main() -> None:
    from areas.registry import area_names

    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--planner", default="classic")
    parser.add_argument("--areas", nargs="+", default=None,
                        help="area names (default: all 11 built-in areas)")
    parser.add_argument("--runs", type=int, default=PAPER_RUNS, help="runs per area")
    parser.add_argument("--time-scale", type=float, default=1.0,
                        help="fraction (0-1] of each area's plateau time a run lasts")
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--preset", default="default")
    args = parser.parse_args()
    builtin = area_names()
    args.areas = args.areas or builtin
    unknown = sorted(set(args.areas) - set(builtin))
    if unknown:
        parser.error(f"unknown area(s) {', '.join(unknown)}; known: {', '.join(builtin)}")
    if not 0 < args.time_scale <= 1:
        parser.error("--time-scale must be in (0, 1]")
    print(f"{args.planner} on {', '.join(args.areas)}: {args.runs} run(s) each at "
          f"{args.time_scale:g} x the plateau time; workers {args.workers}", flush=True)
    results = []
    for n in args.workers:
        result = measure(n, args, builtin)
        print(f"{n} worker(s): {result['status']} in {result['wall_s']} s "
              f"({result['simulated_s']:.0f} simulated s; API start-up "
              f"{result['startup_s']} s, area sync {result['area_sync_s']} s before submitting)",
              flush=True)
        results.append(result)
    plateau = results[0].pop("plateau_s")
    for r in results[1:]:
        r.pop("plateau_s")
    full_suite_s = PAPER_RUNS * sum(plateau[a] for a in builtin)
    asked_s = args.runs * args.time_scale * sum(plateau[a] for a in args.areas)
    base_wall = results[0]["wall_s"]
    rows = []
    for r in results:
        projected = full_suite_s / r["sim_per_wall"] if r["sim_per_wall"] else float("nan")
        rows.append([r["workers"], r["status"], f"{r['wall_s']:.1f}", f"{r['simulated_s']:.0f}",
                     f"{r['sim_per_wall']:.2f}", f"{base_wall / r['wall_s']:.2f}",
                     f"{r['worker_cpu_s']:.0f}", f"{r['worker_cores_busy']:.2f}",
                     f"{1000 * r['worker_cpu_per_sim_s']:.1f}", f"{r['api_cpu_s']:.0f}",
                     _hours(projected), _hours(PAPER_SUITE_WALL_S)])
        r["projected_full_suite_s"] = projected
        r["speedup"] = base_wall / r["wall_s"]
    print_table(f"suite wall time: {args.planner}, {len(args.areas)} area(s) x {args.runs} "
                f"run(s), time scale {args.time_scale:g}",
                ["workers", "status", "wall s", "simulated s", "sim s / wall s", "speed-up",
                 "worker CPU s", "worker cores busy", "worker CPU ms / sim s", "API CPU s",
                 "full suite at this rate", "paper"], rows)
    print_table("per run", ["workers", "area", "seed", "sim s", "status", "worker wall s"],
                [[r["workers"], x["area"], x["seed"], x["seconds"], x["status"],
                  f"{x['wall_s']:.1f}" if x["wall_s"] is not None else "-"]
                 for r in results for x in r["runs"]])
    path = write_json("suite_wall", {
        "planner": args.planner, "areas": args.areas, "runs": args.runs,
        "time_scale": args.time_scale, "preset": args.preset, "asked_simulated_s": asked_s,
        "full_suite_simulated_s": full_suite_s, "paper_full_suite_wall_s": PAPER_SUITE_WALL_S,
        "load_average": os.getloadavg(), "results": results})
    print(f"\nwritten {path}")


if __name__ == "__main__":
    main()
