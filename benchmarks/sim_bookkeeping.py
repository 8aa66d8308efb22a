"""The CPU time of a run's bookkeeping, this build against another, on the same map.

    nice -n 10 .venv/bin/python benchmarks/sim_bookkeeping.py --old OLD_CHECKOUT \\
        [--areas facility-c maze]

For each area and build, in a process of its own with one thread per library: 20 frames from
the start (80 x 60 rays each) are fused into a fresh map, then each piece of bookkeeping is
timed after one more fused frame, seven times, and the least CPU time kept: the FREE and
OCCUPIED masks a plan reads, the frontier clusters, a map keyframe, the safety monitor's copy
of the map, a recall snapshot (20,000 truth points against a TSDF of 16 full frames) and one
physics step (`World.step`, hovering near the start).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from benchmarks.common import print_table, write_json  # noqa: E402
from worker.threads import thread_environment  # noqa: E402

COSTS = ("masks_ms", "clusters_ms", "keyframe_ms", "guard_ms", "recall_ms", "step_us")


def child(root: Path, area_name: str) -> dict[str, float]:
    sys.path.insert(0, str(root))
    import numpy as np

    from areas import load_area, load_ground_truth
    from sim.camera import DepthCamera
    from sim.config import preset
    from sim.flight import startup_spin
    from sim.geometry import Pose
    from sim.map_view import MappingStack
    from sim.measures.series import subsample
    from sim.recording import RecordingWriter
    from sim.safety_monitor import SafetyMonitor
    from sim.stage_costs import StageCosts
    from sim.trajectory import TrajectorySample
    from sim.tsdf import TsdfVolume
    from sim.world import World

    area, cfg = load_area(area_name), preset("default")
    stack = MappingStack(area.bounds_min, area.grid_shape, area.voxel_size,
                         cfg.safety_radius_m, cfg.occupancy)
    camera = DepthCamera(area.vertices, area.triangles, cfg.camera)
    here = area.start.position

    def fuse(yaw: float) -> None:
        pose = Pose(here.copy(), yaw)
        ends, hit = camera.back_project(camera.render(pose, stride=2).depth, pose, 2)
        stack.occupancy.integrate(here, ends, hit)

    def least(fn: Callable[[], object], calls: int = 7) -> float:
        best = float("inf")
        for i in range(calls):
            fuse(0.3 * i)
            t0 = time.process_time()
            fn()
            best = min(best, time.process_time() - t0)
        return best

    for yaw in np.linspace(0.0, 6.2, 20):
        fuse(float(yaw))
    out = {"masks_ms": 1e3 * least(lambda: (stack.view().free, stack.view().occupied)),
           "clusters_ms": 1e3 * least(lambda: stack.frontiers.clusters())}
    writer = RecordingWriter(header={})
    writer.map_keyframe(0.0, stack.occupancy.state)
    try:  # a build whose keyframes follow the map's dirty boxes
        from sim.episode_recorder import _NOTHING
        changes = stack.occupancy.subscribe()
        out["keyframe_ms"] = 1e3 * least(lambda: writer.map_keyframe(
            1.0, stack.occupancy.state, changes.take() or _NOTHING))
    except ImportError:
        out["keyframe_ms"] = 1e3 * least(lambda: writer.map_keyframe(1.0, stack.occupancy.state))
    monitor = SafetyMonitor(cfg, stack, StageCosts())
    flight = startup_spin(np.array([*here, 0.0]), 0.0, cfg.limits)
    out["guard_ms"] = 1e3 * least(lambda: monitor.guard(flight, 0))
    tsdf = TsdfVolume(cfg.camera.intrinsic_matrix(), cfg.camera.max_range_m, cfg.tsdf)
    for yaw in np.linspace(0.0, 6.28, 16):
        pose = Pose(here.copy(), float(yaw))
        tsdf.integrate(camera.render(pose).depth, pose)
    points = subsample(load_ground_truth(area).surface_points, cfg.recall_sample_points)
    out["recall_ms"] = 1e3 * least(lambda: tsdf.sdf_at(points))
    world = World(area.vertices, area.triangles, here, cfg.limits, cfg.physics)
    hold = TrajectorySample(here + np.array([0.3, 0.1, 0.05]), np.array([0.1, 0.0, 0.0]),
                            np.zeros(3), 0.0, 0.0)
    steps = 2000
    out["step_us"] = 1e6 * least(lambda: [world.step(hold) for _ in range(steps)], 3) / steps
    world.close()
    return out


def run_child(root: Path, area: str) -> dict[str, float]:
    done = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--child",
                           "--root", str(root), "--area", area],
                          env=thread_environment(1, os.environ), cwd=root, capture_output=True,
                          text=True, check=False)
    if done.returncode != 0:
        raise SystemExit(f"{root} on {area} failed:\n{done.stderr[-3000:]}")
    return dict(json.loads(done.stdout.strip().splitlines()[-1]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--old", type=Path, help="a checkout of the build to compare against")
    parser.add_argument("--new", type=Path, default=ROOT)
    parser.add_argument("--areas", nargs="+", default=["facility-c", "maze"])
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--root", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--area", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(child(args.root.resolve(), args.area)))
        return
    if args.old is None or not (args.old / "sim" / "episode.py").is_file():
        parser.error("--old must name a checkout of the build to compare against")
    rows: list[dict[str, Any]] = []
    for area in args.areas:
        old, new = run_child(args.old.resolve(), area), run_child(args.new.resolve(), area)
        rows.append({"area": area, "old": old, "new": new})
    print_table("Least CPU time of 7 calls, old -> new (physics: microseconds per step)",
                ["area", *COSTS],
                [[r["area"], *(f"{r['old'][k]:.2f} -> {r['new'][k]:.2f}" for k in COSTS)]
                 for r in rows])
    path = write_json("sim_bookkeeping", {
        "command": "python benchmarks/sim_bookkeeping.py " + " ".join(sys.argv[1:]),
        "old": str(args.old), "new": str(args.new), "areas": rows,
    })
    print(f"\nwrote {path}")


if __name__ == "__main__":
    main()
