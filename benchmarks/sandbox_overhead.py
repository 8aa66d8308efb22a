"""Per-iteration planning time of Classic on MAZE in process and in the sandbox.

Same seed and preset `exact` (planning time not charged, so both runs fly the same path and
make the same calls); the target is a median at most 5 ms above in-process. Run pinned to one
core for the planner side: `taskset -c 0 .venv/bin/python benchmarks/sandbox_overhead.py`
(the sandboxed planner process inherits the mask).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import print_table, write_json


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seconds", type=float, default=300.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--repeats", type=int, default=3, help="runs of each mode, alternated")
    args = parser.parse_args()
    from areas import load_area, load_ground_truth
    from planners.registry import make
    from sim.config import preset
    from sim.episode import run_episode
    from worker.sandbox.isolation import probe
    from worker.sandbox.proxy import SandboxedPlanner

    area = load_area("maze")
    truth = load_ground_truth(area)
    config = preset("exact")
    # Alternate the two modes so that a change in machine load hits both alike.
    times: dict[str, list[float]] = {"in process": [], "sandbox": []}
    results: dict[str, Any] = {}
    walls = {"in process": 0.0, "sandbox": 0.0}
    reported: list[dict[str, float]] = []
    sandbox_totals: list[float] = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        direct = run_episode(area, truth, make("classic"), config, args.seed,
                             seconds=args.seconds)
        t1 = time.perf_counter()
        with SandboxedPlanner(builtin="classic") as planner:
            boxed = run_episode(area, truth, planner, config, args.seed, seconds=args.seconds)
            reported += planner.timings[1:]
        t2 = time.perf_counter()
        walls["in process"] += t1 - t0
        walls["sandbox"] += t2 - t1
        times["in process"] += list(direct.planning_times_ms[1:])
        times["sandbox"] += list(boxed.planning_times_ms[1:])
        sandbox_totals += list(boxed.planning_times_ms[1:])
        results = {"in process": direct, "sandbox": boxed}
    rows = []
    summary = {}
    for name in ("in process", "sandbox"):
        result = results[name]
        later = np.asarray(times[name])  # the first call of each run includes warm-up
        summary[name] = {"iterations": int(result.iterations),
                         "median_ms": float(np.median(later)),
                         "p90_ms": float(np.percentile(later, 90)),
                         "wall_s": walls[name],
                         "explored_m3": float(result.explored_volume_m3)}
        rows.append([name, result.iterations, f"{np.median(later):.2f}",
                     f"{np.percentile(later, 90):.2f}", f"{walls[name]:.1f}",
                     f"{result.explored_volume_m3:.1f}"])
    overhead = summary["sandbox"]["median_ms"] - summary["in process"]["median_ms"]
    # Where a sandboxed call's time goes, as the planner process measured it.
    total = np.asarray(sandbox_totals)
    map_ms = np.array([t.get("map", 0.0) for t in reported])
    plan_ms = np.array([t.get("plan", 0.0) for t in reported])
    breakdown = {"planner_ms": float(np.median(plan_ms)),
                 "map_refresh_ms": float(np.median(map_ms)),
                 "transport_ms": float(np.median(total - map_ms - plan_ms))}
    print_table("a sandboxed call, medians", ["part", "ms"],
                [[k, f"{v:.2f}"] for k, v in breakdown.items()])
    print_table(f"Classic on MAZE, {args.seconds:g} s, seed {args.seed}, preset exact, "
                f"{args.repeats} runs of each",
                ["planner runs", "iterations", "median ms", "p90 ms", "wall s",
                 "explored m³"], rows)
    print(f"\nmedian overhead of the sandbox: {overhead:+.2f} ms (target <= +5 ms); "
          f"isolation notes: {probe().notes or 'none'}")
    path = write_json("sandbox_overhead", {"seconds": args.seconds, "seed": args.seed,
                                           "runs": summary, "median_overhead_ms": overhead,
                                           "sandboxed_call": breakdown,
                                           "target_ms": 5.0})
    print(f"written {path}")


if __name__ == "__main__":
    main()
