"""Simulated seconds per wall second on every area, and where a frame's time goes.

    taskset -c 0 .venv/bin/python benchmarks/sim_speed_areas.py [--areas all] [--seconds 120]
        [--planner classic] [--preset default] [--out NAME]

`--seconds plateau` flies each area for its plateau time, as a published run does: a short
window weighs the run's one-time costs (building the physics scene, the start's clearance,
the final mesh and its scoring) more than a whole run does, and a whole run plans over a larger
map later on.

Each row carries the run's fingerprint (`tests/sim/episode_fingerprints.py`: its result less
what measures the machine): with the `exact` preset, which charges no planning time, two trees
that compute the same flight print the same fingerprint, so their times compare one flight.

The title names the machine's speed factor (`sim.reference_speed`: the reference workload's
time on the reference machine over its time here), so that tables measured on machines of
different speed can be told apart; the stages do not all scale with it.

One episode per area in this process (pin it to one core: Open3D may otherwise use both), after
a 5 s episode on MAZE that loads (or compiles) the numba kernels. The per-frame costs are per
fused camera frame; "planner" is the planning time per simulated second, the rest of the wall
time (trajectory generation, bookkeeping) is "other".
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import flybo  # noqa: F401  before NumPy loads: it pins the CPU kernels (flybo.cpu_kernels)
from areas import area_names, load_area, load_ground_truth
from benchmarks.common import peak_rss_mib, print_table, write_json
from flybo.versions import benchmark_version
from planners.registry import make, spec
from sim.config import preset
from sim.episode import run_episode
from sim.reference_speed import REFERENCE_CPU_S, speed_factor
from tests.sim.episode_fingerprints import fingerprint

STAGES = ("render", "occupancy", "tsdf", "physics", "metrics", "checks", "recording")


def measure(area_name: str, planner: str, preset_name: str, seconds: float | None,
            seed: int) -> dict[str, Any]:
    """One episode; `seconds` None flies the area's plateau time."""
    area = load_area(area_name)
    truth = load_ground_truth(area)
    config = preset(preset_name)
    started = time.perf_counter()
    result = run_episode(area, truth, make(planner), config, seed,
                         planner_name=spec(planner).id, preset_name=preset_name,
                         seconds=area.plateau_s if seconds is None else seconds)
    wall = time.perf_counter() - started
    simulated = result.simulated_until
    costs = result.frame_costs_ms
    every = min(config.occupancy_every_n_frames, config.tsdf_every_n_frames)
    frames = simulated * config.camera.rate_hz / every
    planning_s = float(sum(result.planning_times_ms)) / 1000.0
    accounted = sum(costs.get(k, 0.0) for k in STAGES) * frames / 1000.0 + planning_s
    return {
        "area": area_name, "simulated_s": simulated, "wall_s": wall,
        "realtime_factor": simulated / wall, "status": result.status.value,
        "coverage": result.coverage, "frame_costs_ms": costs, "fused_frames": frames,
        "planning_s": planning_s, "other_s": max(wall - accounted, 0.0),
        "grid_voxels": int(area.grid_shape[0] * area.grid_shape[1] * area.grid_shape[2]),
        "faces": len(area.triangles),
        "fingerprint": fingerprint(result.to_json())[:12],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--areas", nargs="+", default=["all"])
    parser.add_argument("--seconds", default="120",
                        help="simulated seconds per area, or 'plateau' (each area's)")
    parser.add_argument("--out", default="sim_speed_areas", help="name of the JSON written")
    parser.add_argument("--planner", default="classic")
    parser.add_argument("--preset", default="default")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    names = area_names() if args.areas == ["all"] else args.areas
    seconds = None if args.seconds == "plateau" else float(args.seconds)
    warm = load_area("maze")
    run_episode(warm, load_ground_truth(warm), make(args.planner), preset(args.preset), 0,
                seconds=5.0)
    rows = []
    for name in names:
        row = measure(name, args.planner, args.preset, seconds, args.seed)
        rows.append(row)
        print(f"{name}: {row['realtime_factor']:.1f} simulated s per wall s", flush=True)
    # Figures from machines of different speed differ by tens of percent: name this one's.
    factor = speed_factor()
    print_table(
        f"{spec(args.planner).id}, preset {args.preset}, {args.seconds} simulated s per area, "
        f"machine speed factor {factor:.2f} (reference workload {REFERENCE_CPU_S / factor:.3f} s "
        f"against {REFERENCE_CPU_S:.3f})",
        ["area", "faces", "grid voxels", "sim s", "sim s / wall s",
         *(f"{k} ms/frame" for k in STAGES), "planning s", "other s", "wall s", "fingerprint"],
        [[r["area"], r["faces"], r["grid_voxels"], f"{r['simulated_s']:.0f}",
          f"{r['realtime_factor']:.1f}",
          *(f"{r['frame_costs_ms'].get(k, 0.0):.2f}" for k in STAGES),
          f"{r['planning_s']:.1f}", f"{r['other_s']:.1f}", f"{r['wall_s']:.1f}",
          r["fingerprint"]] for r in rows],
    )
    path = write_json(args.out, {
        "command": "python benchmarks/sim_speed_areas.py " + " ".join(sys.argv[1:]),
        "benchmark": benchmark_version(), "planner": spec(args.planner).id,
        "preset": args.preset, "seconds": args.seconds,
        "seed": args.seed, "speed_factor": factor, "peak_rss_mib": peak_rss_mib(),
        "areas": rows,
    })
    print(f"\nwrote {path}")


if __name__ == "__main__":
    main()
