"""What a second run beside the first costs: one episode alone, then two at once, in rounds.

    .venv/bin/python benchmarks/concurrent_runs.py [--area offices-a] [--seconds 240]
        [--planner classic] [--rounds 3] [--pin]

Each episode runs in its own process (as a worker's run does), after a 5 s MAZE episode that
loads the compiled kernels. Per process: wall time, CPU time (all its threads) and the cores it
kept busy (CPU / wall). A run alone may use more than one core: Open3D casts rays and fuses the
TSDF on every core it may use. Two workers on two cores cannot then finish a suite more than
2 / (cores one run keeps busy) times faster than one, however evenly they split it; the table
gives that bound and the throughput two at once actually reached (2 x wall alone / wall two at
once). Rounds alternate alone and two at once, so that drift in the machine's speed falls on
both. `--pin` puts each of the two on its own core (taskset), the run alone on one core.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks.common import print_table, write_json


def _child(area_name: str, planner: str, seconds: float, seed: int) -> None:
    from areas import load_area, load_ground_truth
    from planners.registry import make, spec
    from sim.config import preset
    from sim.episode import run_episode

    config = preset("default")
    warm = load_area("maze")
    run_episode(warm, load_ground_truth(warm), make(planner), config, seed,
                planner_name=spec(planner).id, preset_name="default", seconds=5.0)
    area = load_area(area_name)
    truth = load_ground_truth(area)
    wall0, cpu0 = time.perf_counter(), time.process_time()
    result = run_episode(area, truth, make(planner), config, seed,
                         planner_name=spec(planner).id, preset_name="default", seconds=seconds)
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    print(json.dumps({"wall_s": wall, "cpu_s": cpu, "simulated_s": result.simulated_until}))


def _launch(args: argparse.Namespace, cores: list[int | None]) -> list[dict[str, Any]]:
    """Start one process per entry of `cores` at once (pinned to that core, or not when
    None); their measurements."""
    command = [sys.executable, __file__, "--child", "--area", args.area, "--planner",
               args.planner, "--seconds", str(args.seconds), "--seed", str(args.seed)]
    procs = [subprocess.Popen((["taskset", "-c", str(core)] if core is not None else [])
                              + command, stdout=subprocess.PIPE, text=True)
             for core in cores]
    results = []
    for proc in procs:
        out, _ = proc.communicate()
        if proc.returncode != 0:
            raise SystemExit(f"an episode process failed ({proc.returncode})")
        results.append(json.loads(out.strip().splitlines()[-1]))
    return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--area", default="offices-a")
    parser.add_argument("--planner", default="classic")
    parser.add_argument("--seconds", type=float, default=240.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--pin", action="store_true")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        _child(args.area, args.planner, args.seconds, args.seed)
        return
    if args.rounds < 1 or args.seconds <= 0:
        parser.error("--rounds must be at least 1 and --seconds positive")
    cores = sorted(os.sched_getaffinity(0))
    if args.pin and len(cores) < 2:
        parser.error("--pin needs two cores")
    alone_cores: list[int | None] = [cores[0]] if args.pin else [None]
    two_cores: list[int | None] = list(cores[:2]) if args.pin else [None, None]
    rows: list[list[Any]] = []
    alone: list[dict[str, Any]] = []
    two: list[dict[str, Any]] = []
    for round_ in range(1, args.rounds + 1):
        for mode, slots, into in (("alone", alone_cores, alone), ("two at once", two_cores, two)):
            measured = _launch(args, slots)
            into.extend(measured)
            for m in measured:
                rows.append([round_, mode, f"{m['wall_s']:.1f}", f"{m['cpu_s']:.1f}",
                             f"{m['cpu_s'] / m['wall_s']:.2f}",
                             f"{m['simulated_s'] / m['wall_s']:.1f}"])
            print(f"round {round_} {mode}: " + ", ".join(f"{m['wall_s']:.1f} s" for m in measured),
                  flush=True)
    print_table(f"{args.planner} on {args.area}, {args.seconds:g} simulated s per run"
                + (", pinned" if args.pin else ""),
                ["round", "mode", "wall s", "CPU s", "cores busy", "sim s / wall s"], rows)
    wall_alone = statistics.mean(m["wall_s"] for m in alone)
    wall_two = statistics.mean(m["wall_s"] for m in two)
    cores_alone = statistics.mean(m["cpu_s"] / m["wall_s"] for m in alone)
    summary = {
        "wall_alone_s": wall_alone, "wall_two_s": wall_two,
        "cpu_alone_s": statistics.mean(m["cpu_s"] for m in alone),
        "cpu_two_s": statistics.mean(m["cpu_s"] for m in two),
        "cores_busy_alone": cores_alone,
        "per_run_slowdown": wall_two / wall_alone,
        "two_at_once_throughput": 2.0 * wall_alone / wall_two,
        "bound_from_cores_alone": len(two_cores) / cores_alone,
    }
    print_table("summary (means)", ["quantity", "value"],
                [[k, f"{v:.2f}"] for k, v in summary.items()])
    path = write_json("concurrent_runs", {
        "area": args.area, "planner": args.planner, "seconds": args.seconds, "seed": args.seed,
        "pinned": args.pin, "rounds": args.rounds, "load_average": os.getloadavg(),
        "alone": alone, "two": two, "summary": summary})
    print(f"\nwritten {path}")


if __name__ == "__main__":
    main()
