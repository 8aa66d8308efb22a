"""The TSDF's cost per fused frame over a whole run, in windows of simulated time.

    taskset -c 0 .venv/bin/python benchmarks/tsdf_growth.py [--area warehouse] [--seconds S]
        [--window 100] [--planner classic]

One episode (default preset, seed 0, the area's plateau time unless `--seconds`). For each
window: the TSDF's wall time per frame it fused, the part of it spent growing the block table
(`TsdfVolume._make_room`), the voxel blocks each frame touched, the time per touched block, and
the blocks allocated at the window's end. A cost per touched block that stays flat while the
table grows says the integration costs what a frame sees, not what the map holds.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import flybo  # noqa: F401  before NumPy: it pins the CPU kernels
from areas import load_area, load_ground_truth
from benchmarks.common import print_table, write_json
from planners.registry import make, spec
from sim import sensing, tsdf
from sim.config import preset
from sim.episode import run_episode
from sim.geometry import Pose


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--area", default="warehouse")
    parser.add_argument("--seconds", type=float, default=None)
    parser.add_argument("--window", type=float, default=100.0)
    parser.add_argument("--planner", default="classic")
    args = parser.parse_args()
    area = load_area(args.area)
    truth = load_ground_truth(area)
    # Per window: integrate s, growth s, frames, touched blocks, blocks at the end.
    windows: dict[int, list[float]] = defaultdict(lambda: [0.0, 0.0, 0, 0, 0])
    now = [0.0]
    integrate, make_room, frame = (tsdf.TsdfVolume.integrate, tsdf.TsdfVolume._make_room,
                                   sensing.Sensing.frame)

    def window() -> list[float]:
        return windows[int(now[0] // args.window)]

    def timed_integrate(self: tsdf.TsdfVolume, depth: Any, pose: Pose) -> None:
        started = time.perf_counter()
        integrate(self, depth, pose)
        w = window()
        w[0] += time.perf_counter() - started
        w[2] += 1
        w[4] = self._grid.hashmap().size()

    def timed_room(self: tsdf.TsdfVolume, touched: int) -> None:
        started = time.perf_counter()
        make_room(self, touched)
        w = window()
        w[1] += time.perf_counter() - started
        w[3] += touched

    def stamped(self: sensing.Sensing, stamp: float, true_pose: Pose) -> None:
        now[0] = stamp
        frame(self, stamp, true_pose)

    tsdf.TsdfVolume.integrate = timed_integrate  # type: ignore[method-assign]
    tsdf.TsdfVolume._make_room = timed_room  # type: ignore[method-assign]
    sensing.Sensing.frame = stamped  # type: ignore[method-assign]
    seconds = area.plateau_s if args.seconds is None else args.seconds
    try:
        run_episode(area, truth, make(args.planner), preset("default"), 0, seconds=seconds)
    finally:
        tsdf.TsdfVolume.integrate = integrate  # type: ignore[method-assign]
        tsdf.TsdfVolume._make_room = make_room  # type: ignore[method-assign]
        sensing.Sensing.frame = frame  # type: ignore[method-assign]
    rows = []
    for k in sorted(windows):
        total, growth, frames, touched, blocks = windows[k]
        n = max(int(frames), 1)
        rows.append({
            "from_s": k * args.window, "to_s": (k + 1) * args.window, "frames": int(frames),
            "ms_per_frame": 1000.0 * total / n, "growth_ms_per_frame": 1000.0 * growth / n,
            "touched_per_frame": touched / n,
            "us_per_touched_block": 1e6 * (total - growth) / max(touched, 1),
            "blocks": int(blocks),
        })
    print_table(
        f"TSDF per fused frame, {spec(args.planner).id} on {area.name}, {seconds:g} s",
        ["window s", "frames", "ms / frame", "growth ms / frame", "blocks touched / frame",
         "us / touched block", "blocks allocated"],
        [[f"{r['from_s']:g}-{r['to_s']:g}", r["frames"], f"{r['ms_per_frame']:.2f}",
          f"{r['growth_ms_per_frame']:.2f}", f"{r['touched_per_frame']:.0f}",
          f"{r['us_per_touched_block']:.1f}", r["blocks"]] for r in rows],
    )
    path = write_json("tsdf_growth", {
        "command": "python benchmarks/tsdf_growth.py " + " ".join(sys.argv[1:]),
        "area": area.name, "planner": spec(args.planner).id, "seconds": seconds,
        "window_s": args.window, "windows": rows,
    })
    print(f"\nwrote {path}")


if __name__ == "__main__":
    main()
