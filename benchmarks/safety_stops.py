"""Safety stops against collisions: the same runs with the in-flight check on and off.

    .venv/bin/python benchmarks/safety_stops.py [--cases splatplanner:offices-b,aep-v1:platform-a]
        [--seeds 0] [--seconds S] [--jobs 2] [--modes on,off]

By default, the seven (planner, area) runs that collided in the six-planner suite of
`docs/RESULTS.md`, at seed 0, the default preset and the area's plateau time. Each run is one
episode in its own process, `--jobs` at a time; on and off alternate in the queue, so that a
drift in the machine's speed falls on both. The planner's wall time is charged to the simulated
clock (as in the suite), so a run is not repeatable to the step: compare counts over several runs.
Per run: how it ended, simulated time, coverage, F-score, safety stops, path length, wall time,
and the wall time the check took (the `checks` frame cost: the path checks and the copy of the
map each accepted plan is checked against), in seconds and as a share of the run.
"""

from __future__ import annotations

import argparse
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks.common import print_table, write_json

SUITE_COLLISIONS = ("splatplanner:offices-b,splatplanner:offices-c,splatplanner:platform-a,"
                    "splatplanner:platform-b,aep-v1:facility-c,aep-v1:offices-b,aep-v1:platform-a")


def _run(planner: str, area_name: str, seed: int, seconds: float | None,
         safety_stops: bool) -> dict[str, Any]:
    from areas import load_area, load_ground_truth
    from planners.registry import make, spec
    from sim.config import preset
    from sim.episode import run_episode

    config = preset("default").model_copy(update={"safety_stops": safety_stops})
    area = load_area(area_name)
    truth = load_ground_truth(area)
    wall0 = time.perf_counter()
    result = run_episode(area, truth, make(planner), config, seed, planner_name=spec(planner).id,
                         preset_name="default", seconds=seconds)
    return {
        "planner": spec(planner).id, "area": area_name, "seed": seed,
        "safety_stops_on": safety_stops, "status": result.status.value, "reason": result.reason,
        "simulated_until": result.simulated_until, "coverage": result.coverage,
        "fscore": result.surface.fscore, "safety_stops": result.safety_stops,
        "collisions": result.collisions, "path_length_m": result.path_length_m,
        "wall_s": time.perf_counter() - wall0,
        # Fused frames, as `sim_speed_areas.py` counts them: the costs are per fused frame.
        "check_s": result.frame_costs_ms["checks"] / 1000.0 * result.simulated_until
        * config.camera.rate_hz / min(config.occupancy_every_n_frames,
                                      config.tsdf_every_n_frames),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cases", default=SUITE_COLLISIONS,
                        help="comma-separated planner:area pairs")
    parser.add_argument("--seeds", default="0", help="comma-separated seeds")
    parser.add_argument("--seconds", type=float, default=None,
                        help="simulated seconds (default: each area's plateau time)")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--modes", default="on,off",
                        help="'on', 'off' or both: run with the check on, off, or each in turn")
    args = parser.parse_args()
    modes = [m.strip() for m in args.modes.split(",")]
    if not modes or any(m not in ("on", "off") for m in modes):
        parser.error(f"--modes takes on and/or off, got {args.modes!r}")
    cases = []
    for item in args.cases.split(","):
        planner, sep, area = item.strip().partition(":")
        if not sep or not planner or not area:
            parser.error(f"a case is planner:area, got {item!r}")
        cases.append((planner, area))
    seeds = [int(s) for s in args.seeds.split(",")]
    queue = [(p, a, seed, args.seconds, on) for p, a in cases for seed in seeds
             for on in (m == "on" for m in modes)]
    with ProcessPoolExecutor(max_workers=args.jobs, max_tasks_per_child=1) as pool:
        runs = list(pool.map(_run, *zip(*queue, strict=True)))
    rows = [[r["planner"], r["area"], r["seed"], "on" if r["safety_stops_on"] else "off",
             r["status"], f"{r['simulated_until']:.0f}", f"{100 * r['coverage']:.1f}",
             f"{100 * r['fscore']:.1f}", r["safety_stops"], f"{r['path_length_m']:.0f}",
             f"{r['wall_s']:.0f}", f"{r['check_s']:.2f}",
             f"{100 * r['check_s'] / r['wall_s']:.1f}"] for r in runs]
    print_table("Safety stops on and off", ["planner", "area", "seed", "stops", "status",
                                            "until s", "coverage %", "F %", "stops made",
                                            "path m", "wall s", "check s", "check %"], rows)
    summary = {on: [r for r in runs if r["safety_stops_on"] == on] for on in (True, False)}
    for on, group in summary.items():
        if not group:
            continue
        crashed = sum(r["status"] == "crashed" for r in group)
        print(f"safety stops {'on' if on else 'off'}: {crashed} of {len(group)} runs crashed, "
              f"{sum(r['safety_stops'] for r in group)} stops made")
    path = write_json("safety_stops", {"cases": args.cases, "seeds": seeds, "runs": runs})
    print(f"\nwrote {path}")


if __name__ == "__main__":
    main()
