"""Planners flown with the depth camera's range set: what a longer (or shorter) range changes.

    .venv/bin/python benchmarks/sensor_range.py --planners esm-ipp splatplanner \
        --areas powerplant --seeds 0 1 2 --ranges 5 7 [--seconds S] [--name NAME]

The benchmark's camera reaches 5 m for every planner (`docs/presets.md`). Some published
configurations flew a method with another range on some areas (the FLYBO authors' ESM on
WAREHOUSE, PLATFORM A-B and POWERPLANT: a 7 m sensor and 7 m gain rays, `docs/planners/esm.md`);
this script measures how much of a difference between our results and a paper's such a range
accounts for. It does not change the benchmark: the runs are diagnostics, flown with the default
preset's every other setting and each planner's default config, except that a planner whose
config casts gain rays to a fixed length (`gain_range_m`) casts them as far as the camera reaches
(`--keep-gain-range` leaves them at their default).

One run per planner, area, seed and range, one after the other in this process. Prints the
coverage and F-score of each run and the mean per planner, area and range; writes JSON.
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
from areas.registry import UnknownAreaError
from benchmarks.common import print_table, write_json
from flybo.versions import benchmark_version
from planners.registry import UnknownPlannerError, make, spec
from sim.config import EpisodeConfig, preset
from sim.episode import run_episode


def episode_config(range_m: float) -> EpisodeConfig:
    """The default preset with the camera reaching `range_m`."""
    base = preset("default")
    return base.model_copy(update={"camera": base.camera.model_copy(
        update={"max_range_m": range_m})})


def planner_config(planner_id: str, range_m: float, keep_gain_range: bool) -> dict[str, Any]:
    """The planner's config overrides: gain rays as long as the camera's range, where the
    planner's config has a fixed gain-ray length."""
    fields = spec(planner_id).config_model.model_fields
    if keep_gain_range or "gain_range_m" not in fields:
        return {}
    return {"gain_range_m": range_m}


def fly(planner_id: str, area_name: str, seed: int, range_m: float, seconds: float | None,
        keep_gain_range: bool) -> dict[str, Any]:
    area = load_area(area_name)
    pid = spec(planner_id).id
    overrides = planner_config(pid, range_m, keep_gain_range)
    t0 = time.perf_counter()
    result = run_episode(area, load_ground_truth(area), make(pid, overrides),
                         episode_config(range_m), seed, planner_name=pid,
                         preset_name=f"default, camera {range_m:g} m", seconds=seconds)
    return {
        "planner": pid, "area": area_name, "seed": seed, "camera_range_m": range_m,
        "planner_config": overrides, "coverage": result.coverage,
        "fscore": result.surface.fscore, "status": result.status.value,
        "reason": result.reason, "ended_at_s": result.simulated_until,
        "iterations": result.iterations, "path_length_m": result.path_length_m,
        "collisions": result.collisions, "wall_s": time.perf_counter() - t0,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--planners", nargs="+", required=True)
    parser.add_argument("--areas", nargs="+", required=True)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--ranges", type=float, nargs="+", default=[5.0, 7.0],
                        help="camera ranges, metres")
    parser.add_argument("--seconds", type=float, default=None,
                        help="simulated seconds (default: each area's plateau time)")
    parser.add_argument("--keep-gain-range", action="store_true",
                        help="leave a planner's gain-ray length at its default")
    parser.add_argument("--name", default="sensor_range", help="JSON file name in results/")
    args = parser.parse_args()
    for r in args.ranges:
        if r <= 0:
            parser.error(f"--ranges: {r:g} is not a positive range in metres")
    try:  # unknown names fail here, before any flight
        for planner_id in args.planners:
            spec(planner_id)
        for area_name in args.areas:
            load_area(area_name)
    except (UnknownPlannerError, UnknownAreaError) as exc:
        parser.error(str(exc))
    runs = []
    for area_name in args.areas:
        for seed in args.seeds:
            for range_m in args.ranges:
                for planner_id in args.planners:
                    run = fly(planner_id, area_name, seed, range_m, args.seconds,
                              args.keep_gain_range)
                    runs.append(run)
                    print(f"{area_name} seed {seed} camera {range_m:g} m {run['planner']}: "
                          f"coverage {run['coverage']:.4f}, F {run['fscore']:.3f}, "
                          f"{run['iterations']} plans, {run['reason']}, "
                          f"{run['wall_s']:.0f} s wall", flush=True)
    print_table(
        "Runs", ["area", "seed", "camera m", "planner", "coverage %", "F-score", "plans",
                 "collisions", "end"],
        [[r["area"], r["seed"], f"{r['camera_range_m']:g}", r["planner"],
          f"{100 * r['coverage']:.1f}", f"{r['fscore']:.3f}", r["iterations"], r["collisions"],
          f"{r['reason']} at {r['ended_at_s']:.0f} s"] for r in runs])
    cells: dict[tuple[str, float, str], list[dict[str, Any]]] = {}
    for r in runs:
        cells.setdefault((r["area"], r["camera_range_m"], r["planner"]), []).append(r)
    print_table(
        "Mean per planner, area and camera range",
        ["area", "camera m", "planner", "runs", "coverage % (least-most)", "F-score"],
        [[area, f"{range_m:g}", pid, len(rs),
          f"{100 * np.mean([r['coverage'] for r in rs]):.1f} "
          f"({100 * min(r['coverage'] for r in rs):.1f}-"
          f"{100 * max(r['coverage'] for r in rs):.1f})",
          f"{np.mean([r['fscore'] for r in rs]):.3f}"]
         for (area, range_m, pid), rs in sorted(cells.items())])
    path = write_json(args.name, {
        "command": "python benchmarks/sensor_range.py " + " ".join(sys.argv[1:]),
        "benchmark": benchmark_version(), "runs": runs,
    })
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
