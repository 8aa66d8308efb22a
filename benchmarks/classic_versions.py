"""Coverage and end of the exploration of two planner versions, area by area and seed by seed.

    .venv/bin/python benchmarks/classic_versions.py \
        [--planners classic-v1 classic-v2] [--areas offices-b facility-c offices-c platform-a] \
        [--seeds 0 1 2] [--preset default] [--seconds S]

Each run flies to the area's plateau time (or `--seconds`). The table gives, per run, the
coverage, the time the run ended and why, and the share of the flight spent on frontier targets
in the lowest 0.3 m of the grid (the floor layer, where the voxels a floor slab's surface shares
with grazing rays stay frontier for good). `docs/notes/2026-12-classic-visited-frontiers.md`
holds the figures this script gave and what they mean.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from areas import load_area, load_ground_truth
from benchmarks.common import print_table, write_json
from planners.registry import make, spec
from sim.config import preset
from sim.episode import run_episode
from sim.interface import Observation, Plan

FLOOR_VOXELS = 3  # targets with k < 3 lie in the lowest 0.3 m of a 0.1 m grid


def _floor_share(planner: Any) -> dict[str, float]:
    """Wrap `planner.plan` to time the flight between plans by the kind of the last target."""
    spent = {"floor_s": 0.0, "other_s": 0.0}
    last: list[tuple[float, bool] | None] = [None]
    inner = planner.plan

    def plan(obs: Observation) -> Plan:
        previous = last[0]
        if previous is not None:
            spent["floor_s" if previous[1] else "other_s"] += obs.time - previous[0]
        result = inner(obs)
        target = getattr(planner, "_target", None)
        last[0] = None if result.done or target is None else (
            obs.time, int(target[2]) < FLOOR_VOXELS)
        return result

    planner.plan = plan
    return spent


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--planners", nargs="+", default=["classic-v1", "classic-v2"])
    parser.add_argument("--areas", nargs="+",
                        default=["offices-b", "facility-c", "offices-c", "platform-a"])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--preset", default="default")
    parser.add_argument("--seconds", type=float, default=None)
    args = parser.parse_args()
    runs = []
    for area_name in args.areas:
        area = load_area(area_name)
        truth = load_ground_truth(area)
        for seed in args.seeds:
            for planner_id in args.planners:
                pid = spec(planner_id).id
                planner = make(pid)
                spent = _floor_share(planner)
                t0 = time.perf_counter()
                result = run_episode(area, truth, planner, preset(args.preset), seed,
                                     planner_name=pid, preset_name=args.preset,
                                     seconds=args.seconds)
                flown = spent["floor_s"] + spent["other_s"]
                runs.append({
                    "area": area_name, "seed": seed, "planner": pid,
                    "coverage": result.coverage, "status": result.status.value,
                    "reason": result.reason, "ended_at_s": result.simulated_until,
                    "floor_share": spent["floor_s"] / flown if flown > 0 else 0.0,
                    "iterations": result.iterations, "collisions": result.collisions,
                    "wall_s": time.perf_counter() - t0,
                })
                r = runs[-1]
                print(f"{area_name} seed {seed} {pid}: coverage {r['coverage']:.3f}, "
                      f"{r['reason']} at {r['ended_at_s']:.0f} s, {r['wall_s']:.0f} s wall",
                      flush=True)
    print_table(
        f"Coverage and end, preset {args.preset}",
        ["area", "seed", "planner", "coverage %", "ended at s", "why", "floor share"],
        [[r["area"], r["seed"], r["planner"], f"{100 * r['coverage']:.1f}",
          f"{r['ended_at_s']:.0f}", r["reason"], f"{r['floor_share']:.2f}"] for r in runs],
    )
    path = write_json("classic_versions", {
        "command": "python benchmarks/classic_versions.py " + " ".join(sys.argv[1:]),
        "preset": args.preset, "runs": runs,
    })
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
