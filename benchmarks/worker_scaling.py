"""Two workers against one, with and without the thread limit per worker process.

    .venv/bin/python benchmarks/worker_scaling.py [--areas maze offices-a] [--episodes 8]
        [--seconds 60] [--planner classic] [--rounds 2] [--setups 1:one 2:shared]

A fifth of a planner's suite (each built-in area once, seed 0, for its plateau time, the
duration the service gives a run), one worker on one thread against two limited workers:

    .venv/bin/python benchmarks/worker_scaling.py --areas all --episodes 11 --seconds plateau \
        --setups 1:one 2:shared

A "worker" here is a process started with the environment `flybo serve --workers N` gives
each worker (`flybo.worker_processes.worker_environment`: the usable cores shared out,
"limited"), with one thread whatever the cores ("one thread"), or, without the limit, with the
thread variables removed (every library then uses every core). One worker on one thread is
what two workers on two cores are measured against for linear scaling: each of them flies on
one thread. Each worker loads the areas,
flies a 5 s MAZE warm-up (the compiled kernels), limits Open3D as a run in `flybo worker` does
(`worker.threads.limit_open3d`), then waits; when all are ready they take the `--episodes`
episodes (the areas in turn, default preset, seeds 0, 1, ...) from one shared queue, one at a
time, as workers take runs. The time measured is from the start signal to the last episode's
end. Speedup: one worker's time over two workers' time, for the same episodes. Rounds
alternate the set-ups (`--setups`, by default all five), so that drift in the machine's speed
falls on all of them.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import flybo  # noqa: F401  before NumPy loads: it pins the CPU kernels (flybo.cpu_kernels)
from areas import area_names
from areas.registry import all_area_names
from benchmarks.common import print_table, write_json
from flybo.versions import benchmark_version
from flybo.worker_processes import worker_environment
from worker.threads import LIBRARY_VARIABLES, THREADS_ENV, usable_cores

# (workers, threads): "none" removes the limit, "shared" shares the usable cores out among the
# workers (`flybo serve --workers N`), "one" gives each worker one thread.
SETUPS = ((1, "none"), (1, "shared"), (1, "one"), (2, "none"), (2, "shared"))
LABELS = {"none": "no limit", "shared": "limited", "one": "one thread"}


def _child(folder: Path, planner: str, seconds: float | None) -> None:
    """One worker: warm up, report ready, wait for the start, fly queued episodes."""
    from areas import load_area, load_ground_truth
    from planners.registry import make, spec
    from sim.config import preset
    from sim.episode import run_episode
    from worker.threads import limit_open3d, thread_report

    limit_open3d()
    config = preset("default")
    planner_id = spec(planner).id
    tasks = json.loads((folder / "tasks.json").read_text())
    areas = {name: load_area(name) for name in {t["area"] for t in tasks} | {"maze"}}
    truths = {name: load_ground_truth(area) for name, area in areas.items()}
    run_episode(areas["maze"], truths["maze"], make(planner), config, 0, planner_name=planner_id,
                preset_name="default", seconds=5.0)
    (folder / f"ready-{os.getpid()}").write_text(thread_report())
    while not (folder / "go").exists():
        time.sleep(0.01)
    done = []
    for index, task in enumerate(tasks):
        try:  # the claim: one rename wins
            os.rename(folder / "queue" / str(index), folder / "queue" / f"{index}.{os.getpid()}")
        except FileNotFoundError:
            continue
        wall0, cpu0 = time.perf_counter(), time.process_time()
        area = areas[task["area"]]
        result = run_episode(area, truths[task["area"]], make(planner), config, task["seed"],
                             planner_name=planner_id, preset_name="default",
                             seconds=area.plateau_s if seconds is None else seconds)
        done.append({**task, "wall_s": time.perf_counter() - wall0,
                     "cpu_s": time.process_time() - cpu0, "end": time.time(),
                     "simulated_s": result.simulated_until})
    (folder / f"done-{os.getpid()}.json").write_text(json.dumps(done))


def _environment(workers: int, threads: str) -> dict[str, str]:
    if threads == "shared":
        return worker_environment(workers)
    if threads == "one":
        return worker_environment(workers, 1)
    return {k: v for k, v in os.environ.items() if k not in (*LIBRARY_VARIABLES, THREADS_ENV)}


def _measure(args: argparse.Namespace, workers: int, threads: str) -> dict[str, Any]:
    """The K episodes flown by `workers` worker processes; their time from the start signal."""
    with tempfile.TemporaryDirectory(prefix="flybo-scaling-") as name:
        folder = Path(name)
        tasks = [{"area": args.areas[i % len(args.areas)], "seed": i // len(args.areas)}
                 for i in range(args.episodes)]
        (folder / "tasks.json").write_text(json.dumps(tasks))
        (folder / "queue").mkdir()
        for index in range(len(tasks)):
            (folder / "queue" / str(index)).touch()
        command = [sys.executable, __file__, "--child", str(folder), "--planner", args.planner,
                   "--seconds", str(args.seconds)]
        env = _environment(workers, threads)
        load = os.getloadavg()[0]  # other work on the machine: the measurement's noise
        procs = [subprocess.Popen(command, env=env) for _ in range(workers)]
        while len(list(folder.glob("ready-*"))) < workers:
            if any(p.poll() not in (None, 0) for p in procs):
                raise SystemExit("a worker process failed while starting")
            time.sleep(0.05)
        reported = sorted({p.read_text() for p in folder.glob("ready-*")})
        start = time.time()
        (folder / "go").touch()
        for proc in procs:
            if proc.wait() != 0:
                raise SystemExit(f"a worker process failed ({proc.returncode})")
        episodes = [e for p in folder.glob("done-*.json") for e in json.loads(p.read_text())]
    return {"workers": workers, "limit": threads, "threads": reported, "load_1min": load,
            "wall_s": max(e["end"] for e in episodes) - start,
            "episode_wall_s": sum(e["wall_s"] for e in episodes),
            "cpu_s": sum(e["cpu_s"] for e in episodes), "episodes": episodes}


def _setups(parser: argparse.ArgumentParser, given: list[str]) -> list[tuple[int, str]]:
    """`--setups`' WORKERS:LIMIT pairs, checked."""
    setups: list[tuple[int, str]] = []
    for text in given:
        workers, _, threads = text.partition(":")
        if not workers.isdecimal() or int(workers) < 1 or threads not in LABELS:
            parser.error(f"--setups: {text!r} is not WORKERS:LIMIT with LIMIT one of "
                         + ", ".join(LABELS))
        if (int(workers), threads) not in setups:
            setups.append((int(workers), threads))
    return setups


def _label(workers: int, threads: str) -> str:
    return f"{workers} worker{'s' if workers > 1 else ''}, {LABELS[threads]}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--areas", nargs="+", default=["maze", "offices-a"],
                        help="area names, or 'all' (the built-in areas)")
    parser.add_argument("--episodes", type=int, default=8)
    parser.add_argument("--seconds", default="60",
                        help="simulated seconds per episode, or 'plateau' (each area's)")
    parser.add_argument("--planner", default="classic")
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--setups", nargs="+", default=[f"{w}:{t}" for w, t in SETUPS],
                        help="WORKERS:LIMIT pairs, LIMIT one of " + ", ".join(LABELS)
                        + " (default: all five)")
    parser.add_argument("--child", type=Path, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    try:
        seconds = None if args.seconds == "plateau" else float(args.seconds)
    except ValueError:
        parser.error(f"--seconds must be a number or 'plateau', not {args.seconds!r}")
    if args.child is not None:
        _child(args.child, args.planner, seconds)
        return
    if args.areas == ["all"]:
        args.areas = area_names()
    unknown = sorted(set(args.areas) - set(all_area_names()))
    if unknown:
        parser.error(f"--areas: unknown area(s) {', '.join(unknown)}; known: "
                     + ", ".join(all_area_names()) + ", or 'all'")
    setups = _setups(parser, args.setups)
    if args.rounds < 1 or args.episodes < 2 or (
            seconds is not None and not (math.isfinite(seconds) and seconds > 0)):
        parser.error("--rounds must be at least 1, --episodes 2 and --seconds positive")
    measured: dict[tuple[int, str], list[dict[str, Any]]] = {s: [] for s in setups}
    rows = []
    for round_ in range(1, args.rounds + 1):
        for workers, threads in setups:
            m = _measure(args, workers, threads)
            measured[workers, threads].append(m)
            simulated = sum(e["simulated_s"] for e in m["episodes"])
            rows.append([round_, _label(workers, threads), f"{m['wall_s']:.1f}",
                         f"{m['cpu_s']:.1f}", f"{m['cpu_s'] / m['wall_s']:.2f}",
                         f"{simulated / m['wall_s']:.1f}", f"{m['load_1min']:.1f}"])
            print(f"round {round_} {_label(workers, threads)}: {m['wall_s']:.1f} s  "
                  f"({'; '.join(m['threads'])})", flush=True)
    duration = "each area's plateau time" if seconds is None else f"{seconds:g} s"
    print_table(f"{args.episodes} x {duration} of {args.planner} on "
                f"{', '.join(args.areas)}, {usable_cores()} usable cores",
                ["round", "set-up", "wall s", "CPU s", "cores busy", "sim s / wall s",
                 "load before"], rows)
    wall = {s: statistics.mean(m["wall_s"] for m in ms) for s, ms in measured.items()}
    comparisons = {
        "2 vs 1 worker, limited (flybo serve now)": ((1, "shared"), (2, "shared")),
        "2 vs 1 worker, no limit (before)": ((1, "none"), (2, "none")),
        "2 limited vs 1 without limit": ((1, "none"), (2, "shared")),
        "2 limited vs 1 on one thread": ((1, "one"), (2, "shared")),
        "2 workers: limited over no limit": ((2, "none"), (2, "shared")),
        "1 worker: limited over no limit": ((1, "none"), (1, "shared")),
        "1 worker: one thread over limited": ((1, "shared"), (1, "one")),
    }
    ratios = {name: wall[a] / wall[b] for name, (a, b) in comparisons.items()
              if a in wall and b in wall}
    print_table("speedup (mean wall times; > 1: the first set-up is faster)",
                ["comparison", "speedup"], [[k, f"{v:.2f}x"] for k, v in ratios.items()])
    path = write_json("worker_scaling", {
        "command": "python benchmarks/worker_scaling.py " + " ".join(sys.argv[1:]),
        "benchmark": benchmark_version(),
        "areas": args.areas, "episodes": args.episodes,
        "seconds": "plateau" if seconds is None else seconds,
        "planner": args.planner, "rounds": args.rounds, "usable_cores": usable_cores(),
        "load_average_after": os.getloadavg(),
        "mean_wall_s": {_label(*s): v for s, v in wall.items()}, "speedup": ratios,
        "measurements": {_label(*s): ms for s, ms in measured.items()}})
    print(f"\nwritten {path}")


if __name__ == "__main__":
    main()
