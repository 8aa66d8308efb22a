"""A run's bookkeeping at its end, each operation beside the one it replaced, on the same state.

    taskset -c 0 .venv/bin/python benchmarks/bookkeeping_ops.py [--areas offices-a warehouse
        facility-c] [--seconds plateau] [--repeats 3] [--baseline DIR]

Flies Classic (default preset, seed 0) for each area's plateau time (or `--seconds`), then,
on the run's final TSDF and mesh, times each operation and its reference, alternating, the
fastest of `--repeats` each, and says whether their results agree:

- surface points (the recording's snapshots): `sim.tsdf_points.crossing_points` against
  Open3D's `extract_point_cloud`;
- thinning a snapshot to 10 cm cells: the bitmap against sorted cell keys;
- the TSDF read at the 20,000 points of the recall over time: `sim.tsdf_sampling` against
  reading through Open3D's block table (`hashmap().find`);
- every mesh vertex's distance to the area's surface: `sim.mesh_distance` against Open3D's
  `RaycastingScene.compute_distance` (float32; "agree" counts vertices more than 10 µm apart);
- the final recall's within-tau count: `sim.cell_lists.share_within` against scipy's k-d tree;
- the final mesh: `sim.tsdf_mesh.marching_cubes` against Open3D's `extract_triangle_mesh` of
  the whole grid ("agree": `sim.tsdf_mesh.same_mesh`, the same vertices to the bit and the
  same triangles with their winding).

With `--baseline DIR` (an unpacked `git archive` of another commit), the surface points are
also timed against that tree's `sim/tsdf_points.py` on the same grid, and must be identical,
in the same order; and the final mesh against that tree's (`sim/tsdf_mesh.py`, or before it
`sim/tsdf_slabs.py`, Open3D's marching cubes in slabs), and must be the same mesh.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import numpy as np
from scipy.spatial import cKDTree

import sim.recording
from areas import load_area, load_ground_truth
from benchmarks.common import baseline_module, print_table, write_json
from planners.registry import make, spec
from sim.camera import DepthCamera
from sim.cell_lists import share_within
from sim.config import preset
from sim.episode_loop import EpisodeLoop
from sim.mesh_distance import distance_to_mesh
from sim.metrics import TIE_TOLERANCE_M
from sim.open3d_any import o3c
from sim.planning_charge import PlanningCharge
from sim.reference_speed import speed_factor
from sim.tsdf import TsdfVolume
from sim.tsdf_mesh import marching_cubes, open3d_mesh, same_mesh
from sim.tsdf_points import crossing_points


def fastest(repeats: int, *calls: Callable[[], Any]) -> tuple[list[float], list[Any]]:
    """Each call's least wall time over `repeats` alternating rounds, and its last result."""
    best = [float("inf")] * len(calls)
    out: list[Any] = [None] * len(calls)
    for _ in range(repeats):
        for i, call in enumerate(calls):
            t0 = time.perf_counter()
            out[i] = call()
            best[i] = min(best[i], time.perf_counter() - t0)
    return best, out


def read_through_table(tsdf: TsdfVolume, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The field at `points`, corner by corner through Open3D's block table (as `sdf_at` read
    it before `sim.tsdf_sampling`)."""
    cfg = tsdf.config
    res = cfg.block_resolution
    scaled = np.asarray(points, dtype=np.float64) / cfg.voxel_size_m
    base = np.floor(scaled).astype(np.int64)
    frac = scaled - base
    values = tsdf.grid.attribute("tsdf").reshape((-1,))
    weights = tsdf.grid.attribute("weight").reshape((-1,))
    sdf = np.zeros(len(points))
    weight = np.full(len(points), np.inf, dtype=np.float32)
    for corner in np.ndindex(2, 2, 2):
        off = np.array(corner)
        vox = base + off
        block = np.floor_divide(vox, res)
        local = vox - block * res
        buf, found = tsdf.grid.hashmap().find(o3c.Tensor(block.astype(np.int32)))
        hit = np.flatnonzero(found.numpy().astype(bool))
        value = np.zeros(len(vox))
        w = np.zeros(len(vox), dtype=np.float32)
        flat = buf.numpy().astype(np.int64)[hit] * res**3 + (
            (local[hit, 2] * res + local[hit, 1]) * res + local[hit, 0])
        value[hit] = values[o3c.Tensor(flat)].numpy().reshape(-1)
        w[hit] = weights[o3c.Tensor(flat)].numpy().reshape(-1)
        sdf += np.prod(np.where(off == 1, frac, 1.0 - frac), axis=1) * value
        weight = np.minimum(weight, w)
    unseen = ~(weight > 0)
    sdf[unseen] = np.nan
    weight[unseen] = 0.0
    return sdf * cfg.voxel_size_m * cfg.trunc_voxel_multiplier, weight


def rows_sorted(points: np.ndarray) -> np.ndarray:
    return points[np.lexsort(points.T[::-1])]


def baseline_crossing_points(tree: Path) -> Callable[..., np.ndarray]:
    """`crossing_points` of another tree's `sim/tsdf_points.py`."""
    found: Callable[..., np.ndarray] = baseline_module(
        tree, "sim/tsdf_points.py", "baseline_tsdf_points").crossing_points
    return found


def baseline_mesh(tree: Path) -> Callable[..., tuple[np.ndarray, np.ndarray]]:
    """The final mesh of another tree: its `sim/tsdf_mesh.py::marching_cubes`, or (before that
    module) its `sim/tsdf_slabs.py::mesh_in_slabs`."""
    if (tree / "sim" / "tsdf_mesh.py").exists():
        found: Callable[..., tuple[np.ndarray, np.ndarray]] = baseline_module(
            tree, "sim/tsdf_mesh.py", "baseline_tsdf_mesh").marching_cubes
    else:
        found = baseline_module(tree, "sim/tsdf_slabs.py", "baseline_tsdf_slabs").mesh_in_slabs
    return found


def measure(area_name: str, seconds: float | None, repeats: int,
            baseline: Path | None = None) -> list[dict[str, Any]]:
    area = load_area(area_name)
    truth = load_ground_truth(area)
    config = preset("default")
    planner = make("classic")
    loop = EpisodeLoop(area, truth, config, 0, spec("classic").id, "default",
                       area.plateau_s if seconds is None else seconds, None)
    try:
        result = loop.run_with(planner, PlanningCharge(config.planning_time_charge,
                                                       speed_factor(), planner), ())
        tsdf = loop.sensing.tsdf
        cfg = tsdf.config
        grid = tsdf.grid
        vertices = np.asarray(result.mesh_vertices, dtype=np.float64)
        camera = DepthCamera(area.vertices, area.triangles, config.camera)
        recall_points = truth.surface.sample(config.recall_sample_points)
        final_points = truth.surface.sample(config.final_recall_points)
        bound = float(np.nextafter(config.surface_tau_m + TIE_TOLERANCE_M, np.inf))
        ops: list[dict[str, Any]] = []

        def add(name: str, times: list[float], agree: str) -> None:
            ops.append({"area": area_name, "operation": name, "ours_s": times[0],
                        "reference_s": times[1], "ratio": times[0] / times[1],
                        "agree": agree})

        times, (ours, ref) = fastest(
            repeats, lambda: crossing_points(grid, cfg.voxel_size_m, cfg.weight_threshold),
            lambda: grid.extract_point_cloud(cfg.weight_threshold).point.positions.numpy())
        same = np.array_equal(rows_sorted(ours), rows_sorted(ref))
        add(f"surface points ({len(ours):,})", times, "identical" if same else "DIFFER")
        if baseline is not None:
            before = baseline_crossing_points(baseline)
            times, (ours, ref) = fastest(
                repeats, lambda: crossing_points(grid, cfg.voxel_size_m, cfg.weight_threshold),
                lambda: before(grid, cfg.voxel_size_m, cfg.weight_threshold))
            same = ours.shape == ref.shape and np.array_equal(ours.view(np.uint32),
                                                               ref.view(np.uint32))
            add("surface points, against --baseline", times,
                "identical, same order" if same else "DIFFER")

        points = ours
        saved = sim.recording.MAX_BITMAP_CELLS

        def by_sorting() -> np.ndarray:
            sim.recording.MAX_BITMAP_CELLS = 0
            try:
                return sim.recording.thinned(points, config.surface_snapshot_voxel_m)
            finally:
                sim.recording.MAX_BITMAP_CELLS = saved

        times, (ours, ref) = fastest(
            repeats, lambda: sim.recording.thinned(points, config.surface_snapshot_voxel_m),
            by_sorting)
        add("thinning a snapshot", times, "identical" if np.array_equal(ours, ref) else "DIFFER")

        times, (ours, ref) = fastest(repeats, lambda: tsdf.sdf_at(recall_points),
                                     lambda: read_through_table(tsdf, recall_points))
        same = np.array_equal(ours[0], ref[0], equal_nan=True) and np.array_equal(ours[1], ref[1])
        add(f"TSDF at {len(recall_points):,} points", times, "identical" if same else "DIFFER")

        times, (ours, ref) = fastest(
            repeats, lambda: distance_to_mesh(area.vertices, area.triangles, vertices),
            lambda: camera.distance_to_surface_many(vertices))
        apart = int(np.count_nonzero(np.abs(ours - ref) > 1e-5))
        add(f"vertex distances ({len(vertices):,})", times,
            f"{apart:,} over 10 µm apart (max {1000 * float(np.max(ref - ours)):.2f} mm nearer)")

        times, (ours, ref) = fastest(
            repeats, lambda: share_within(vertices, final_points, bound),
            lambda: float(np.count_nonzero(np.isfinite(cKDTree(vertices).query(
                final_points, k=1, distance_upper_bound=bound)[0]))) / len(final_points))
        add("recall count", times, "identical" if ours == ref else "DIFFER")

        times, (ours, ref) = fastest(repeats, tsdf.mesh,
                                     lambda: open3d_mesh(grid, cfg.weight_threshold))
        add(f"final mesh ({len(ours[0]):,} vertices)", times,
            "the same mesh" if same_mesh(ours, ref) else "DIFFER")
        if baseline is not None:
            mesh_before = baseline_mesh(baseline)
            times, (ours, ref) = fastest(
                repeats, lambda: marching_cubes(grid, cfg.voxel_size_m, cfg.weight_threshold),
                lambda: mesh_before(grid, cfg.voxel_size_m, cfg.weight_threshold))
            add("final mesh, against --baseline", times,
                "the same mesh" if same_mesh(ours, ref) else "DIFFER")
        return ops
    finally:
        loop.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--areas", nargs="+", default=["offices-a", "warehouse", "facility-c"])
    parser.add_argument("--seconds", default="plateau")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", default="bookkeeping_ops")
    parser.add_argument("--baseline", type=Path, default=None,
                        help="another tree's folder, whose surface points and mesh are timed too")
    args = parser.parse_args()
    seconds = None if args.seconds == "plateau" else float(args.seconds)
    ops = [op for name in args.areas for op in measure(name, seconds, args.repeats, args.baseline)]
    print_table("A run's bookkeeping at its end: ours against the reference (s, fastest of "
                f"{args.repeats})", ["area", "operation", "ours s", "reference s", "ratio",
                                     "results"],
                [[o["area"], o["operation"], f"{o['ours_s']:.3f}", f"{o['reference_s']:.3f}",
                  f"{o['ratio']:.2f}", o["agree"]] for o in ops])
    print(f"wrote {write_json(args.out, {'operations': ops, 'repeats': args.repeats})}")


if __name__ == "__main__":
    main()
