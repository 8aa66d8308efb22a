"""Coverage of MAZE by Classic at the plateau (700 s), seeds 0-4, default preset.

    .venv/bin/python benchmarks/maze_classic_coverage.py [--seeds 0 1 2 3 4]

Target: coverage >= 0.90 of the observable volume with no collision on every seed.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from areas import load_area, load_ground_truth
from benchmarks.common import peak_rss_mib, print_table, write_json
from planners.registry import make, spec
from sim.config import preset
from sim.episode import run_episode

# The newest original Classic, named by its id in the results.
CLASSIC = spec("classic").id


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    parser.add_argument("--preset", default="default")
    args = parser.parse_args()
    area = load_area("maze")
    truth = load_ground_truth(area)
    runs = []
    for seed in args.seeds:
        t0 = time.perf_counter()
        result = run_episode(area, truth, make(CLASSIC), preset(args.preset), seed,
                             planner_name=CLASSIC, preset_name=args.preset)
        wall = time.perf_counter() - t0
        volume_at = dict(zip(result.volume_times.round().astype(int), result.volume_m3,
                             strict=True))
        runs.append({
            "seed": seed, "status": result.status.value, "reason": result.reason,
            "coverage": result.coverage, "collisions": result.collisions,
            "explored_volume_m3": result.explored_volume_m3,
            "volume_at_s": {t: float(volume_at[t]) for t in (100, 300, 500, 700) if t in volume_at},
            "finished_at_s": result.simulated_until, "wall_s": wall,
            "path_length_m": result.path_length_m, "iterations": result.iterations,
            "fscore": result.surface.fscore, "rmse_m": result.surface.rmse_m,
        })
        print(f"seed {seed}: coverage {result.coverage:.3f}, {result.status.value}, "
              f"{result.collisions} collisions, {wall:.0f} s wall", flush=True)
    print_table(
        f"MAZE + Classic at 700 s, preset {args.preset}",
        ["seed", "coverage", "collisions", "V@300 s", "finished at s", "path m", "F-score",
         "wall s"],
        [[r["seed"], f"{r['coverage']:.3f}", r["collisions"],
          f"{r['volume_at_s'].get(300, float('nan')):.0f}", f"{r['finished_at_s']:.0f}",
          f"{r['path_length_m']:.0f}", f"{r['fscore']:.3f}", f"{r['wall_s']:.0f}"]
         for r in runs],
    )
    ok = all(r["coverage"] >= 0.9 and r["collisions"] == 0 for r in runs)
    print(f"target (coverage >= 0.90, no collision, every seed): {'met' if ok else 'NOT met'}")
    path = write_json("maze_classic_coverage", {
        "command": "python benchmarks/maze_classic_coverage.py " + " ".join(sys.argv[1:]),
        "preset": args.preset, "runs": runs, "target_met": ok, "peak_rss_mib": peak_rss_mib(),
    })
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
