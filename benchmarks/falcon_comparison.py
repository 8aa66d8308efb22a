"""FALCON against FUEL and SplatPlanner on MAZE, OFFICES A and WAREHOUSE at their plateau times,
default preset, one core.

    nice -n 10 .venv/bin/python benchmarks/falcon_comparison.py [--areas maze offices-a warehouse]
        [--planners falcon-v1 fuel-v1 splatplanner-v2] [--seeds 0] [--append]

Runs one episode at a time in this process, with one thread for numba, OpenMP and BLAS. Prints
coverage, time to 90 % coverage, collisions and the median planning time per iteration (every
`plan` call, keep-flying answers included), and writes `results/falcon_comparison.json` after
every run.

Targets: every run >= 0.95 coverage with no collision; FALCON reaches 90 % sooner than FUEL on
at least 2 of the 3 areas; FALCON's median planning time <= 50 ms on WAREHOUSE.
"""

from __future__ import annotations

import os

for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from areas import load_area, load_ground_truth  # noqa: E402
from benchmarks.common import RESULTS, print_table, write_json  # noqa: E402
from planners.registry import make, spec  # noqa: E402
from sim.config import preset  # noqa: E402
from sim.episode import run_episode  # noqa: E402

AREAS = ["maze", "offices-a", "warehouse"]
PLANNERS = ["falcon-v1", "fuel-v1", "splatplanner-v2"]


def run_one(area_name: str, planner: str, seed: int) -> dict[str, Any]:
    area = load_area(area_name)
    t0 = time.perf_counter()
    result = run_episode(area, load_ground_truth(area), make(planner), preset("default"), seed,
                         planner_name=spec(planner).id, preset_name="default")
    planning = result.planning_times_ms
    t90 = result.metrics.get("time_to_90_coverage_s")
    return {
        "area": area_name, "planner": spec(planner).id, "seed": seed,
        "seconds": area.plateau_s, "status": result.status.value, "reason": result.reason,
        "coverage": result.coverage, "time_to_90_s": None if t90 is None else float(t90),
        "collisions": result.collisions, "finished_at_s": result.simulated_until,
        "iterations": result.iterations, "path_length_m": result.path_length_m,
        "planning_ms_median": float(np.median(planning)) if len(planning) else float("nan"),
        "planning_ms_p90": float(np.percentile(planning, 90)) if len(planning) else float("nan"),
        "wall_s": time.perf_counter() - t0,
    }


def verdicts(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """The targets, judged on the runs made."""
    def t90(area: str, planner: str) -> float:
        times = [r["time_to_90_s"] for r in runs if r["area"] == area and r["planner"] == planner]
        if not times or any(t is None for t in times):
            return float("inf")
        return float(np.mean(times))

    areas = sorted({r["area"] for r in runs})
    sooner = [a for a in areas if t90(a, "falcon-v1") < t90(a, "fuel-v1")]
    warehouse = [r["planning_ms_median"] for r in runs
                 if r["area"] == "warehouse" and r["planner"] == "falcon-v1"]
    return {
        "coverage_095_no_collision": {
            p: all(r["coverage"] >= 0.95 and r["collisions"] == 0 for r in runs
                   if r["planner"] == p) for p in sorted({r["planner"] for r in runs})},
        "falcon_90_sooner_than_fuel_on": sooner,
        "falcon_90_sooner_on_2_of_3": len(sooner) >= 2,
        "falcon_warehouse_median_ms_le_50": bool(warehouse) and max(warehouse) <= 50.0,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--areas", nargs="+", default=AREAS)
    parser.add_argument("--planners", nargs="+", default=PLANNERS)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--out", default="falcon_comparison", help="JSON name in results/")
    parser.add_argument("--append", action="store_true",
                        help="keep the runs already in the JSON that these do not replace")
    args = parser.parse_args()
    runs: list[dict[str, Any]] = []
    if args.append and (RESULTS / f"{args.out}.json").exists():
        redo = {(a, spec(p).id, s) for a in args.areas for p in args.planners for s in args.seeds}
        old = json.loads((RESULTS / f"{args.out}.json").read_text())["runs"]
        runs = [r for r in old if (r["area"], r["planner"], r["seed"]) not in redo]
    for area in args.areas:
        for planner in args.planners:
            for seed in args.seeds:
                run = run_one(area, planner, seed)
                runs.append(run)
                print(f"{area} {run['planner']} seed {seed}: coverage {run['coverage']:.3f}, "
                      f"t90 {run['time_to_90_s']}, {run['collisions']} collisions, "
                      f"{run['wall_s']:.0f} s wall", flush=True)
                write_json(args.out, {"runs": runs, "verdicts": verdicts(runs)})
    print_table(
        "Plateau time, default preset, one core",
        ["area", "planner", "seed", "coverage", "t 90 % s", "collisions", "plan ms median",
         "plan ms p90", "iterations", "finished at s", "wall s"],
        [[r["area"], r["planner"], r["seed"], f"{r['coverage']:.3f}",
          "-" if r["time_to_90_s"] is None else f"{r['time_to_90_s']:.0f}", r["collisions"],
          f"{r['planning_ms_median']:.1f}", f"{r['planning_ms_p90']:.1f}", r["iterations"],
          f"{r['finished_at_s']:.0f}", f"{r['wall_s']:.0f}"] for r in runs],
    )
    result = verdicts(runs)
    for key, value in result.items():
        print(f"{key}: {value}")
    path = write_json(args.out, {"runs": runs, "verdicts": result})
    print(f"\nwritten {path}")


if __name__ == "__main__":
    main()
