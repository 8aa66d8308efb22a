"""The full suite's wall time on this machine, estimated per planner from measured CPU time.

The paper's protocol is every planner on the 11 built-in areas, 5 runs each at the plateau
time. `benchmarks/crash_sweep.py` flies each (planner, area) once at the plateau time, in a
process of its own, and records that process's CPU time (`cpu_s`, every thread): what the run
costs whatever else the machine is doing. The estimate of a planner's suite is

    sum over the areas of cpu_s  x  runs  /  busy cores

where `busy cores` is how many cores two worker processes keep busy between them on this
2-core machine (1.73-1.80 measured by `benchmarks/worker_scaling.py`, `docs/performance-service.md`;
default 1.75). The 5 runs of an area differ in seed only, so one run's CPU time stands for each.
A planner with areas not yet flown gets a lower bound, marked as such.

Run: `.venv/bin/python benchmarks/suite_estimate.py [--benchmark V] [--runs 5]
[--busy-cores 1.75] [--log RUNS.jsonl ...]` after (or while) `benchmarks/crash_sweep.py` runs
(`--log`: kept sweeps' runs, `benchmarks/records/`, in place of the sweep's own log; a run of a
later log replaces the same planner's run of that area and seed in an earlier one). The
total counts one version per planner name, the one the name stands for (an older version
flown beside it is listed, not counted). Target: the 7-planner suite under 3 hours
(`docs/PERFORMANCE.md`).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks.common import print_table, write_json
from benchmarks.crash_sweep import LOG, stored_runs


def estimate(runs: list[dict[str, Any]], areas: list[str], *, repeats: int,
             busy_cores: float) -> list[dict[str, Any]]:
    """Per planner: the areas measured, their CPU seconds and the suite's estimated wall time."""
    cpu: dict[str, dict[str, float]] = {}
    for run in runs:
        if run.get("cpu_s") is not None and run["area"] in areas and run["seed"] == 0:
            cpu.setdefault(run["planner"], {})[run["area"]] = float(run["cpu_s"])
    rows = []
    for planner, per_area in sorted(cpu.items()):
        total = sum(per_area.values())
        rows.append({"planner": planner, "areas": len(per_area), "of": len(areas),
                     "cpu_s": total, "wall_min": total * repeats / busy_cores / 60,
                     "complete": len(per_area) == len(areas),
                     "missing": sorted(set(areas) - set(per_area))})
    return rows


def speed_factors(runs: list[dict[str, Any]], planners: list[str]) -> dict[str, Any]:
    """The least and largest machine speed factor recorded by the seed-0 runs of `planners`
    (`sim.reference_speed`; None when none records one), and how many of them record one."""
    counted = [r for r in runs
               if r["planner"] in planners and r["seed"] == 0 and r.get("cpu_s") is not None]
    factors = [float(r["speed_factor"]) for r in counted if r.get("speed_factor") is not None]
    return {"least": min(factors, default=None), "largest": max(factors, default=None),
            "recorded": len(factors), "runs": len(counted)}


def merged_runs(logs: list[list[dict[str, Any]]]) -> list[dict[str, Any]]:
    """The runs of several logs that record their CPU time, a later log's run replacing an
    earlier log's run of the same planner, area and seed."""
    merged: dict[tuple[str, str, int], dict[str, Any]] = {}
    for runs in logs:
        for run in runs:
            if run.get("cpu_s") is not None:
                merged[(run["planner"], run["area"], run["seed"])] = run
    return list(merged.values())


def _current(planner_id: str) -> str:
    """The id the name of `planner_id` stands for now (itself for a name no longer registered,
    such as a third-party planner not installed here)."""
    from planners.registry import UnknownPlannerError, parse_id, spec

    try:
        return spec(parse_id(planner_id)[0]).id
    except (UnknownPlannerError, ValueError):
        return planner_id


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--benchmark", default=None, help="benchmark version (default: the tree's)")
    parser.add_argument("--runs", type=int, default=5, help="runs per area in the suite")
    parser.add_argument("--busy-cores", type=float, default=1.75)
    parser.add_argument("--log", type=Path, nargs="+", action="extend", default=None,
                        help="crash sweeps' runs, a later log's run replacing an earlier's of the "
                             "same planner, area and seed (default: the sweep's log under "
                             "benchmarks/results)")
    parser.add_argument("--name", default="suite_estimate",
                        help="the JSON's name under benchmarks/results/")
    args = parser.parse_args()
    if args.runs < 1 or not args.busy_cores > 0:
        raise SystemExit("--runs must be at least 1 and --busy-cores positive")
    from areas import area_names
    from flybo.versions import benchmark_version

    version = args.benchmark or benchmark_version()
    logs: list[Path] = args.log or [LOG]
    missing = [str(log) for log in logs if not log.is_file()]
    if missing:
        raise SystemExit(f"{', '.join(missing)}: no such file")
    runs = merged_runs([stored_runs(version, log) for log in logs])
    rows = estimate(runs, area_names(), repeats=args.runs, busy_cores=args.busy_cores)
    if not rows:
        named = ", ".join(map(str, logs))
        raise SystemExit(f"no run of benchmark {version} in {named} records its CPU time: run "
                         "benchmarks/crash_sweep.py first")
    print_table(f"Suite wall time estimated from CPU time (benchmark {version}, {args.runs} runs "
                f"per area, {args.busy_cores} busy cores)",
                ["planner", "areas measured", "CPU s, one run per area", "suite, min"],
                [[r["planner"], f"{r['areas']}/{r['of']}", f"{r['cpu_s']:.0f}",
                  f"{r['wall_min']:.1f}" + ("" if r["complete"] else " (lower bound)")]
                 for r in rows])
    counted = [r for r in rows if r["planner"] == _current(r["planner"])]
    total = sum(r["wall_min"] for r in counted)
    complete = all(r["complete"] for r in counted)
    print(f"\nall planners ({', '.join(r['planner'] for r in counted)}): {total / 60:.2f} h"
          f"{'' if complete else ' (lower bound)'}")
    factors = speed_factors(runs, [r["planner"] for r in counted])
    if factors["recorded"]:
        print(f"machine speed factor of these runs: {factors['least']:.2f}-"
              f"{factors['largest']:.2f} ({factors['recorded']} of {factors['runs']} runs "
              "record it): CPU times of days with other factors do not add up")
    else:
        print("machine speed factor of these runs: not recorded")
    path = write_json(args.name, {"benchmark": version, "runs": args.runs,
                                         "busy_cores": args.busy_cores, "planners": rows,
                                         "counted": [r["planner"] for r in counted],
                                         "total_h": total / 60, "complete": complete,
                                         "speed_factor": factors})
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
