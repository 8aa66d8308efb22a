"""Coverage of MAZE by each planner at the plateau (700 s), seeds 0-4, default preset.

    .venv/bin/python benchmarks/planners_maze.py [--planners rapid nbvp aep] [--seeds 0 1 2 3 4]

Targets (fraction of the observable volume, every seed): Rapid >= 0.90, NBVP >= 0.80,
AEP >= 0.85, with no collision.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from areas import load_area, load_ground_truth
from benchmarks.common import peak_rss_mib, print_table, write_json
from planners.registry import make, spec
from sim.config import preset
from sim.episode import run_episode

TARGETS = {"rapid": 0.90, "nbvp": 0.80, "aep": 0.85, "classic": 0.90, "splatplanner": 0.90,
           "esm-ipp": 0.90, "esm-recon": 0.90}


def run_one(planner: str, seed: int, preset_name: str) -> dict[str, Any]:
    area = load_area("maze")
    t0 = time.perf_counter()
    result = run_episode(area, load_ground_truth(area), make(planner), preset(preset_name), seed,
                         planner_name=spec(planner).id, preset_name=preset_name)
    wall = time.perf_counter() - t0
    volume_at = dict(zip(result.volume_times.round().astype(int), result.volume_m3, strict=True))
    planning = result.planning_times_ms
    return {
        "planner": spec(planner).id, "seed": seed, "status": result.status.value,
        "reason": result.reason, "coverage": result.coverage, "collisions": result.collisions,
        "explored_volume_m3": result.explored_volume_m3,
        "volume_at_s": {t: float(volume_at[t]) for t in (100, 300, 500, 700) if t in volume_at},
        "finished_at_s": result.simulated_until, "wall_s": wall,
        "path_length_m": result.path_length_m, "iterations": result.iterations,
        "planning_ms_median": float(np.median(planning)) if len(planning) else float("nan"),
        "fscore": result.surface.fscore,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--planners", nargs="+", default=["rapid", "nbvp", "aep"])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    parser.add_argument("--preset", default="default")
    parser.add_argument("--out", default="planners_maze", help="JSON name in results/")
    args = parser.parse_args()
    runs = []
    for planner in args.planners:
        for seed in args.seeds:
            run = run_one(planner, seed, args.preset)
            runs.append(run)
            print(f"{planner} seed {seed}: coverage {run['coverage']:.3f}, {run['status']} "
                  f"({run['reason']}), {run['collisions']} collisions, {run['wall_s']:.0f} s wall",
                  flush=True)
    print_table(
        f"MAZE at 700 s, preset {args.preset}",
        ["planner", "seed", "coverage", "collisions", "V@300 s", "finished at s", "path m",
         "iterations", "plan ms (median)", "wall s"],
        [[r["planner"], r["seed"], f"{r['coverage']:.3f}", r["collisions"],
          f"{r['volume_at_s'].get(300, float('nan')):.0f}", f"{r['finished_at_s']:.0f}",
          f"{r['path_length_m']:.0f}", r["iterations"], f"{r['planning_ms_median']:.1f}",
          f"{r['wall_s']:.0f}"] for r in runs],
    )
    verdicts = {}
    for planner in args.planners:
        mine = [r for r in runs if r["planner"] == spec(planner).id]
        target = TARGETS.get(planner, 0.0)
        ok = all(r["coverage"] >= target and r["collisions"] == 0 for r in mine)
        verdicts[planner] = ok
        covs = [r["coverage"] for r in mine]
        print(f"{planner}: coverage mean {np.mean(covs):.3f}, min {np.min(covs):.3f}; target "
              f">= {target:.2f} with no collision on every seed: {'met' if ok else 'NOT met'}")
    path = write_json(args.out, {
        "command": "python benchmarks/planners_maze.py " + " ".join(sys.argv[1:]),
        "preset": args.preset, "targets": TARGETS, "runs": runs, "targets_met": verdicts,
        "peak_rss_mib": peak_rss_mib(),
    })
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
