"""What the occupancy map holds of thin parts, and the speckle it keeps: scripted passes.

    .venv/bin/python benchmarks/map_fidelity.py [--seeds 0,1,2] [--baseline DIR]

Two scenes, both fused as the default preset fuses a frame (every other row and column, depth
noise drawn from the seed; true poses):

- **The thin-structure room** (`tests/sim/thin_scenes.py`, 0.1 m voxels): the gallery pass
  toward its rails, 2 cm wires and 4 cm plates, then both door passes. Per thin part's surface
  voxels: how many were ever occupied, how many of those were free again later, how many came to
  hold returns from two frames ("held": the map's protection, `sim.occupancy`) and how many of
  those were free afterwards. Speckle: occupied voxels in free space (cube outside every solid
  and off every surface), ever during the passes and at their end; and the traversable voxels
  at the end (`sim.clearance`, the benchmark's safety radius), which speckle takes from.
- **WAREHOUSE's lamp rods** (2 cm across, 1 m long, in 0.2 m voxels): fly-bys at 1.5 m/s past
  eight rods (four through the middle of their voxels, four along voxel faces), camera along
  the motion, four headings, passing 1.2-3.5 m from the rod's axis,
  from 6 m before it to 3 m after. Once the rod is behind, how many of its voxels are occupied,
  how many hold returns, and how many hold returns yet are FREE, from any number of frames and
  from two or more (a later flight that does not face the rod relies on what the map kept).

`--baseline DIR` runs the same passes with another tree's code (a checkout or an unpacked `git
archive`) in a second process and prints both side by side. Writes
`benchmarks/results/map_fidelity.json`.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent.parent

# WAREHOUSE's lamp rods (`areas/warehouse.py`): x from 2.0 every 2.5 m, y = 8.5 and 12.5 among
# others, from 2.3 m to 1.3 m below the roof truss line (z 9.5-10.5 m). Those at x = 4.5, 9.5 ...
# run through the middle of their 0.2 m voxels, those at x = 7.0, 12.0 ... along voxel faces.
_RODS = [(x, y) for x in (4.5, 7.0, 19.5, 22.0) for y in (8.5, 12.5)]
_ROD_Z = (9.5, 10.5)
_FLYBY_Z = 10.0
_LATERALS_M = (1.2, 1.6, 2.5, 3.5)
_HEADINGS = tuple(0.3 + k * math.pi / 2 for k in range(4))
_STEP_M = 0.3  # 1.5 m/s at the default preset's 5 Hz occupancy fusion


def _thin_room(seed: int) -> dict[str, Any]:
    import numpy as np

    from sim.clearance import TraversabilityTracker
    from sim.config import EpisodeConfig
    from sim.occupancy import VoxelState
    from tests.sim.thin_scenes import (
        DOORS,
        door_pass,
        fly_pass,
        free_space_voxels,
        gallery_pass,
        new_map,
        thin_room,
    )

    area, parts = thin_room()
    free_space = free_space_voxels(area)
    m = new_map(area)
    voxels = np.concatenate([p.surface_voxels(area.bounds_min, area.voxel_size, area.grid_shape)
                             for p in parts])
    voxels = np.unique(voxels, axis=0)
    where = tuple(voxels.T)
    ever_occupied = np.zeros(len(voxels), dtype=bool)
    free_after_occupied = np.zeros(len(voxels), dtype=bool)
    ever_held = np.zeros(len(voxels), dtype=bool)
    free_after_held = np.zeros(len(voxels), dtype=bool)
    speckle_ever = np.zeros(area.grid_shape, dtype=bool)

    def after(_n: int, _pose: object) -> None:
        state = m.state
        occupied = state[where] == VoxelState.OCCUPIED
        free = state[where] == VoxelState.FREE
        free_after_occupied[ever_occupied & free] = True
        free_after_held[ever_held & free] = True
        ever_occupied[occupied] = True
        ever_held[m.returns(voxels)[1] >= 2] = True
        speckle_ever[(state == VoxelState.OCCUPIED) & free_space] = True

    camera = fly_pass(area, m, gallery_pass(), seed=seed, after_frame=after)
    for door in DOORS:
        fly_pass(area, m, door_pass(door), seed=seed, camera=camera, after_frame=after)
    tracker = TraversabilityTracker(m, EpisodeConfig().safety_radius_m)
    tracker.update()
    return {
        "thin_voxels": len(voxels),
        "traversable_end": int(np.count_nonzero(tracker.traversable)),
        "ever_occupied": int(ever_occupied.sum()),
        "free_after_occupied": int(free_after_occupied.sum()),
        "held": int(ever_held.sum()),
        "free_after_held": int(free_after_held.sum()),
        "speckle_ever": int(speckle_ever.sum()),
        "speckle_end": int(np.count_nonzero((m.state == VoxelState.OCCUPIED) & free_space)),
    }


def _rod_voxels(m: Any, x: float, y: float) -> Any:
    """(K, 3) the voxels holding some of a rod's cross-section (1 cm radius) at its heights."""
    import numpy as np

    zs = np.arange(_ROD_Z[0] + 0.01, _ROD_Z[1], 0.02)
    points = [np.stack([np.full_like(zs, x + dx), np.full_like(zs, y + dy), zs], axis=1)
              for dx in (-0.009, 0.009) for dy in (-0.009, 0.009)]
    return np.unique(m.world_to_index(np.concatenate(points)), axis=0)


def _rod_flybys(seed: int) -> dict[str, dict[str, int]]:
    import numpy as np

    from areas.registry import load_area
    from sim.camera import CameraConfig, DepthCamera
    from sim.config import preset
    from sim.geometry import Pose
    from sim.noise import add_depth_noise
    from sim.occupancy import OccupancyMap, VoxelState

    area = load_area("warehouse")
    camera = DepthCamera(area.vertices, area.triangles, CameraConfig())
    cfg = preset("default")
    stride = cfg.occupancy_pixel_stride
    out: dict[str, dict[str, int]] = {}
    for lateral in _LATERALS_M:
        totals = {"rod_voxels": 0, "occupied": 0, "with_returns": 0, "seen_but_free": 0,
                  "held_but_free": 0}
        for k, (x, y) in enumerate(_RODS):
            for h, heading in enumerate(_HEADINGS):
                m = OccupancyMap(area.bounds_min, area.grid_shape, area.voxel_size)
                rng = np.random.default_rng([seed, k, h])
                rod = _rod_voxels(m, x, y)
                along = np.array([math.cos(heading), math.sin(heading), 0.0])
                side = np.array([-along[1], along[0], 0.0])
                centre = np.array([x, y, _FLYBY_Z]) + lateral * side
                for s in np.arange(-6.0, 3.0 + 1e-9, _STEP_M):
                    pose = Pose(centre + s * along, heading)
                    depth = add_depth_noise(camera.render(pose, stride=stride).depth,
                                            cfg.depth_noise, rng)
                    ends, hit = camera.back_project(depth, pose, stride)
                    m.integrate(pose.position, ends, hit)
                state = m.state[tuple(rod.T)]
                count = m.returns(rod)[1]
                totals["rod_voxels"] += len(rod)
                totals["occupied"] += int(np.count_nonzero(state == VoxelState.OCCUPIED))
                totals["with_returns"] += int(np.count_nonzero(count > 0))
                free = state == VoxelState.FREE
                totals["seen_but_free"] += int(np.count_nonzero((count >= 1) & free))
                totals["held_but_free"] += int(np.count_nonzero((count >= 2) & free))
        out[f"{lateral:.1f}"] = totals
    return out


def _measure(seeds: list[int]) -> dict[str, Any]:
    import flybo  # noqa: F401  pins the CPU kernels before NumPy loads, as flights do
    from flybo.versions import benchmark_version

    return {"benchmark": benchmark_version(),
            "thin_room": {str(s): _thin_room(s) for s in seeds},
            "rods": {str(s): _rod_flybys(s) for s in seeds}}


def _in_tree(tree: Path, seeds: list[int]) -> dict[str, Any]:
    cmd = [sys.executable, str(HERE / "benchmarks" / "map_fidelity.py"), "--child-tree",
           str(tree), "--seeds", ",".join(map(str, seeds))]
    out = subprocess.run(cmd, cwd=tree, capture_output=True, text=True)
    if out.returncode != 0:
        tail = "\n".join(out.stderr.strip().splitlines()[-8:])
        raise SystemExit(f"the passes failed with the code of {tree}:\n{tail}")
    return dict(json.loads(out.stdout.strip().splitlines()[-1]))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="0,1,2", help="comma-separated noise seeds")
    parser.add_argument("--baseline", type=Path, default=None,
                        help="another tree's folder, measured beside this one")
    parser.add_argument("--child-tree", type=Path, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    try:
        seeds = [int(s) for s in args.seeds.split(",") if s.strip()]
    except ValueError:
        seeds = []
    if not seeds or min(seeds) < 0:
        raise SystemExit(f"--seeds {args.seeds!r}: give a comma-separated list of integers >= 0")
    if args.child_tree is not None:
        # Every package from that tree (this file's own code imports none of them at the top).
        sys.path.insert(0, str(args.child_tree))
        print(json.dumps(_measure(seeds)))
        return 0
    sys.path.insert(0, str(HERE))
    from benchmarks.common import checked_baseline, print_table, write_json

    baseline = checked_baseline(args.baseline)
    trees = [("this", HERE)] + ([("baseline", baseline)] if baseline else [])
    measured = {label: _in_tree(tree, seeds) for label, tree in trees}
    keys = ["ever_occupied", "free_after_occupied", "held", "free_after_held", "speckle_ever",
            "speckle_end", "traversable_end"]
    rows = [[label, m["benchmark"], seed, r["thin_voxels"], *(r[k] for k in keys)]
            for label, m in measured.items() for seed, r in m["thin_room"].items()]
    print_table("Thin-structure room: gallery and door passes (default preset's fusion)",
                ["tree", "benchmark", "seed", "thin voxels", "ever occupied", "then free",
                 "held (2 frames)", "then free", "speckle ever", "speckle at end",
                 "traversable at end"], rows)
    rows = []
    for label, m in measured.items():
        for lateral in (f"{v:.1f}" for v in _LATERALS_M):
            per_seed = [m["rods"][str(s)][lateral] for s in seeds]
            total = {k: sum(p[k] for p in per_seed) for k in per_seed[0]}
            rows.append([label, m["benchmark"], lateral, total["rod_voxels"], total["occupied"],
                         total["with_returns"], total["seen_but_free"], total["held_but_free"]])
    print_table(f"WAREHOUSE lamp rods after a fly-by (8 rods x 4 headings x seeds {args.seeds})",
                ["tree", "benchmark", "passing at m", "rod voxels", "occupied", "with returns",
                 "with returns, FREE", "two frames' returns, FREE"], rows)
    path = write_json("map_fidelity", {"seeds": seeds, "trees": measured})
    print(f"\nwrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
