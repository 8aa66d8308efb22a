"""The frontier structure a FUEL-family planner (FUEL, FALCON) is left with when its run ends.

    .venv/bin/python benchmarks/frontier_end.py [--planner falcon-v2] [--area offices-b]
        [--seed 0] [--seconds S]

Flies one run (default preset, the area's plateau time unless `--seconds`) and, on the last map
the planner saw, lists its frontier clusters (FUEL's structure with the planner's settings):
size, mean position, how many viewpoints FUEL's sampling finds for each (traversable candidates
on the rings round the cluster's mean that see more than `min_visib_num` of its cells) and how
many of its voxels were given up. Then the same count for the cluster size and minimum frontier
height of FUEL and FALCON on that map. A run that ends with "no coverable frontier" while
clusters remain shows which ones no viewpoint can cover. Writes
`benchmarks/results/frontier_end.json`.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import flybo  # noqa: F401  before NumPy does any work: it pins the CPU kernels
from areas import load_area, load_ground_truth
from benchmarks.common import print_table, write_json
from planners.fuel import FuelPlanner
from planners.fuel_frontier import clusters, sample_viewpoints
from planners.registry import make
from sim.config import preset
from sim.episode import run_episode
from sim.interface import Observation, Plan
from sim.voxel_grid import VoxelState


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--planner", default="falcon-v2")
    parser.add_argument("--area", default="offices-b")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--seconds", type=float, default=None)
    args = parser.parse_args()
    area = load_area(args.area)
    planner = make(args.planner)
    if not isinstance(planner, FuelPlanner):
        raise SystemExit(f"--planner {args.planner}: not a FUEL-family planner")
    last: dict[str, Observation] = {}
    inner = planner.plan

    def plan(obs: Observation) -> Plan:
        last["obs"] = obs
        return inner(obs)

    planner.plan = plan  # type: ignore[method-assign]
    result = run_episode(area, load_ground_truth(area), planner, preset("default"), args.seed,
                         planner_name=args.planner, seconds=args.seconds)
    print(f"{args.planner} on {args.area}, seed {args.seed}: {result.reason} at "
          f"{result.simulated_until:.0f} s, coverage {100 * result.coverage:.1f} %")
    view, cfg, ctx = last["obs"].map, planner.config, planner.context
    mask = planner._give_up.mask
    opaque = view.state != VoxelState.FREE

    def structure(size_xy: float, min_height: float | None) -> list[tuple[Any, int]]:
        min_z = None if min_height is None else float(ctx.bounds_min[2]) + min_height
        found = clusters(view, cfg.cluster_min, size_xy, cfg.down_sample, excluded=mask,
                         min_z_m=min_z, cache={})
        return [(c, len(sample_viewpoints(view, c, planner._offsets, opaque, ctx.camera,
                                          cfg.min_visib_num))) for c in found]

    own = structure(cfg.cluster_size_xy_m, cfg.min_frontier_height_m)
    rows = []
    for cluster, views in own:
        centre = view.index_to_world(cluster.voxels).mean(axis=0)
        given_up = 0 if mask is None else int(mask[tuple(cluster.voxels.T)].sum())
        rows.append([len(cluster.voxels), " ".join(f"{v:.1f}" for v in centre), views, given_up])
    print_table("Frontier clusters on the last map (the planner's settings)",
                ["voxels", "mean x y z (m)", "viewpoints", "given up"], rows)
    variants = []
    for size_xy in (2.0, 2.5):
        for min_height in (0.1, 0.4):
            found = structure(size_xy, min_height)
            variants.append([size_xy, min_height, len(found), sum(1 for _, v in found if v),
                             sum(len(c.voxels) for c, _ in found)])
    print_table("Clusters with viewpoints by cluster size and minimum frontier height",
                ["cluster size xy m", "min height m", "clusters", "with viewpoints", "voxels"],
                variants)
    write_json("frontier_end", {
        "args": vars(args), "reason": result.reason, "until_s": result.simulated_until,
        "coverage": result.coverage, "clusters": rows, "variants": variants})


if __name__ == "__main__":
    main()
