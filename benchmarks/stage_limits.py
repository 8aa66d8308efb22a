"""Each simulation stage against the bare operation it cannot go below, per area, one thread.

    taskset -c 0 .venv/bin/python benchmarks/stage_limits.py [--areas all] [--seconds 60]
        [--planner classic] [--repeats 3]

For each area, the planner flies `--seconds` at the default preset and the true poses of the
frames the run fused are kept. Those frames are then replayed, each stage beside its limit on
the same inputs, alternating, `--repeats` times (the fastest pass of each is kept):

- render: `DepthCamera.render` and the depth noise (the stage's whole work) against Embree's
  `cast_rays` alone on the same rays: rays per second.
- occupancy: back-projection and `OccupancyMap.integrate` into a map replayed from empty,
  against a bare 3D-DDA that walks the same rays through the same grid and only counts the
  voxels it visits: voxel visits per second.
- TSDF: `TsdfVolume.integrate` (the compiled block coordinates and fusion of
  `sim.tsdf_fusion`) against Open3D's own two calls (block coordinates, then integrate) on a
  second volume, the values being the same to the bit: the stage is below 1 where the
  compiled code gains; voxel-block updates per second of Open3D's calls.
- physics: `World.step` tracking a hover reference, against `pybullet.stepSimulation` alone on
  the same scene: steps per second.

Open3D is held to one thread, as a worker's run is (`worker/threads.py`). The ratio column is
the stage's time over its limit's, both measured in this one run, so it does not move with the
machine's speed the way the absolute figures do.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numba
import numpy as np
import numpy.typing as npt
import pybullet

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from areas import area_names, load_area, load_ground_truth
from benchmarks.common import peak_rss_mib, print_table, write_json
from planners.registry import make, spec
from sim import sensing
from sim.camera import DepthCamera
from sim.config import preset
from sim.episode import run_episode
from sim.geometry import Pose
from sim.noise import add_depth_noise
from sim.occupancy import OccupancyMap
from sim.open3d_any import o3d
from sim.trajectory import TrajectorySample
from sim.tsdf import TsdfVolume
from sim.world import World

PHYSICS_STEPS = 2000


@numba.njit(cache=True, inline="always")
def _axis_start(o: float, d: float) -> tuple[int, int, float, float]:
    """One axis of a ray o + t d (voxel units): its first voxel, step, the t of its first
    boundary crossing and the t between crossings."""
    i = math.floor(o)
    if d > 0.0:
        return i, 1, (i + 1.0 - o) / d, 1.0 / d
    if d < 0.0:
        return i, -1, (i - o) / d, -1.0 / d
    return i, 0, math.inf, math.inf


@numba.njit(cache=True)
def _dda_visits(origin: npt.NDArray[np.float64], ends: npt.NDArray[np.float64],
                grid_origin: npt.NDArray[np.float64], voxel: float,
                counts: npt.NDArray[np.uint32]) -> int:
    """Walk each ray origin -> end through the grid (Amanatides-Woo), adding one to every voxel
    it visits inside the grid; the number of visits. The least a ray-by-ray occupancy update
    must do: no log-odds, no state, no hit rules, no allocation."""
    nx, ny, nz = counts.shape
    total = 0
    o0 = (origin[0] - grid_origin[0]) / voxel
    o1 = (origin[1] - grid_origin[1]) / voxel
    o2 = (origin[2] - grid_origin[2]) / voxel
    for r in range(ends.shape[0]):
        d0 = (ends[r, 0] - grid_origin[0]) / voxel - o0
        d1 = (ends[r, 1] - grid_origin[1]) / voxel - o1
        d2 = (ends[r, 2] - grid_origin[2]) / voxel - o2
        i, s0, m0, e0 = _axis_start(o0, d0)
        j, s1, m1, e1 = _axis_start(o1, d1)
        k, s2, m2, e2 = _axis_start(o2, d2)
        t = 0.0
        while t <= 1.0:
            if 0 <= i < nx and 0 <= j < ny and 0 <= k < nz:
                counts[i, j, k] += 1
                total += 1
            if m0 <= m1 and m0 <= m2:
                t = m0
                i += s0
                m0 += e0
            elif m1 <= m2:
                t = m1
                j += s1
                m1 += e1
            else:
                t = m2
                k += s2
                m2 += e2
    return total


def _fused_poses(area_name: str, planner: str, seconds: float, seed: int
                 ) -> tuple[list[Pose], list[bool], dict[str, float], float]:
    """True poses of the frames the run fused, whether the TSDF fused each (then it was
    rendered whole), the run's per-frame stage costs (ms) and its wall s."""
    area = load_area(area_name)
    truth = load_ground_truth(area)
    config = preset("default")
    poses: list[Pose] = []
    whole: list[bool] = []

    original = sensing.Sensing.frame

    def keep(self: sensing.Sensing, stamp: float, true_pose: Pose) -> None:
        i = self.frame_index
        tsdf = i % self.cfg.tsdf_every_n_frames == 0
        if tsdf or i % self.cfg.occupancy_every_n_frames == 0:
            poses.append(true_pose)
            whole.append(tsdf)
        original(self, stamp, true_pose)

    sensing.Sensing.frame = keep  # type: ignore[method-assign]
    try:
        started = time.perf_counter()
        result = run_episode(area, truth, make(planner), config, seed, seconds=seconds)
        wall = time.perf_counter() - started
    finally:
        sensing.Sensing.frame = original  # type: ignore[method-assign]
    return poses, whole, dict(result.frame_costs_ms), wall


def _fastest(passes: int, *work: Callable[[], Any]) -> list[float]:
    """Each callable's fastest of `passes` timed passes, the callables alternating."""
    best = [math.inf] * len(work)
    for _ in range(passes):
        for n, w in enumerate(work):
            t0 = time.perf_counter()
            w()
            best[n] = min(best[n], time.perf_counter() - t0)
    return best


def measure(area_name: str, planner: str, seconds: float, seed: int, repeats: int
            ) -> dict[str, Any]:
    area = load_area(area_name)
    config = preset("default")
    poses, tsdf_frame, episode_costs, wall = _fused_poses(area_name, planner, seconds, seed)
    cam_cfg = config.camera
    camera = DepthCamera(area.vertices, area.triangles, cam_cfg)
    stride = config.occupancy_pixel_stride
    strides = [1 if whole else stride for whole in tsdf_frame]

    # -- render ----------------------------------------------------------------------------
    rays = [o3d.core.Tensor(camera.rays(pose, s)) for pose, s in zip(poses, strides, strict=True)]
    scene = camera._scene
    rng = np.random.default_rng(seed)

    def render_stage() -> None:
        for pose, s in zip(poses, strides, strict=True):
            add_depth_noise(camera.render(pose, 0.0, s).depth, config.depth_noise, rng)

    def render_limit() -> None:
        for r in rays:
            scene.cast_rays(r)

    render_s, cast_s = _fastest(repeats, render_stage, render_limit)
    n_rays = sum(int(r.shape[0]) for r in rays)

    # -- occupancy -------------------------------------------------------------------------
    depths = [camera.render(p, 0.0, s).depth for p, s in zip(poses, strides, strict=True)]
    occ_depths = [d[::stride, ::stride] if s == 1 and stride > 1 else d
                  for d, s in zip(depths, strides, strict=True)]
    ends_hits = [camera.back_project(d, p, stride) for d, p in zip(occ_depths, poses, strict=True)]
    counts = np.zeros(area.grid_shape, dtype=np.uint32)
    visits = [0]

    def occupancy_stage() -> None:
        occ = OccupancyMap(area.bounds_min, area.grid_shape, area.voxel_size, config.occupancy)
        for d, p in zip(occ_depths, poses, strict=True):
            ends, hit = camera.back_project(d, p, stride)
            occ.integrate(p.position, ends, hit)

    def occupancy_limit() -> None:
        counts[...] = 0
        visits[0] = sum(
            _dda_visits(np.asarray(p.position, dtype=np.float64), ends, area.bounds_min,
                        area.voxel_size, counts)
            for p, (ends, _) in zip(poses, ends_hits, strict=True))

    occupancy_s, dda_s = _fastest(repeats, occupancy_stage, occupancy_limit)

    # -- TSDF ------------------------------------------------------------------------------
    whole = [(d, p) for d, p, w in zip(depths, poses, tsdf_frame, strict=True) if w]
    intrinsic = cam_cfg.intrinsic_matrix()
    blocks = [0]

    def tsdf_stage() -> None:
        volume = TsdfVolume(intrinsic, cam_cfg.max_range_m, config.tsdf)
        for d, p in whole:
            volume.integrate(d, p)

    def tsdf_open3d() -> None:
        volume = TsdfVolume(intrinsic, cam_cfg.max_range_m, config.tsdf)
        grid = volume._grid
        k = o3d.core.Tensor(np.asarray(intrinsic, dtype=np.float64))
        mult = config.tsdf.trunc_voxel_multiplier
        touched = 0
        for d, p in whole:
            image = o3d.t.geometry.Image(
                o3d.core.Tensor(np.ascontiguousarray(np.nan_to_num(d, nan=0.0))))
            ext = o3d.core.Tensor(TsdfVolume.extrinsic(p))
            try:
                coords = grid.compute_unique_block_coordinates(image, k, ext, 1.0,
                                                               cam_cfg.max_range_m, mult)
                grid.integrate(coords, image, k, ext, 1.0, cam_cfg.max_range_m, mult)
            except RuntimeError:
                continue
            touched += len(coords)
        blocks[0] = touched

    tsdf_s, tsdf_bare_s = _fastest(repeats, tsdf_stage, tsdf_open3d)

    # -- physics ---------------------------------------------------------------------------
    start = np.asarray(area.start.position, dtype=np.float64)
    hover = TrajectorySample(position=start, velocity=np.zeros(3), acceleration=np.zeros(3),
                             yaw=0.0, yaw_rate=0.0)
    with World(area.vertices, area.triangles, start, config.limits, config.physics) as world:
        cid = world._client

        def physics_stage() -> None:
            for _ in range(PHYSICS_STEPS):
                world.step(hover)

        def physics_limit() -> None:
            for _ in range(PHYSICS_STEPS):
                pybullet.stepSimulation(physicsClientId=cid)

        step_s, bare_step_s = _fastest(repeats, physics_stage, physics_limit)

    frames = len(poses)
    return {
        "area": area_name, "fused_frames": frames, "episode_wall_s": wall,
        "episode_frame_costs_ms": episode_costs, "rays": n_rays,
        "voxel_visits": visits[0], "tsdf_frames": len(whole), "tsdf_blocks": blocks[0],
        "render": {"stage_ms_per_frame": 1000 * render_s / frames,
                   "limit_ms_per_frame": 1000 * cast_s / frames,
                   "limit_rays_per_s": n_rays / cast_s, "ratio": render_s / cast_s},
        "occupancy": {"stage_ms_per_frame": 1000 * occupancy_s / frames,
                      "limit_ms_per_frame": 1000 * dda_s / frames,
                      "limit_visits_per_s": visits[0] / dda_s,
                      "stage_visits_per_s": visits[0] / occupancy_s,
                      "ratio": occupancy_s / dda_s},
        "tsdf": {"stage_ms_per_frame": 1000 * tsdf_s / max(len(whole), 1),
                 "open3d_ms_per_frame": 1000 * tsdf_bare_s / max(len(whole), 1),
                 "open3d_blocks_per_s": blocks[0] / tsdf_bare_s, "ratio": tsdf_s / tsdf_bare_s},
        "physics": {"stage_us_per_step": 1e6 * step_s / PHYSICS_STEPS,
                    "limit_us_per_step": 1e6 * bare_step_s / PHYSICS_STEPS,
                    "ratio": step_s / bare_step_s},
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--areas", nargs="+", default=["all"])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--planner", default="classic")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    o3d.utility.set_max_threads(1)
    names = area_names() if args.areas == ["all"] else args.areas
    warm = load_area("maze")
    run_episode(warm, load_ground_truth(warm), make(args.planner), preset("default"), 0,
                seconds=5.0)
    rows = []
    for name in names:
        row = measure(name, args.planner, args.seconds, args.seed, args.repeats)
        rows.append(row)
        print(f"{name}: {row['fused_frames']} fused frames replayed", flush=True)
    print_table(
        f"{spec(args.planner).id}'s fused frames ({args.seconds:g} s, default preset) replayed "
        "one stage at a time, one thread; stage / limit in the same run",
        ["area", "render ms", "cast ms", "ratio", "Mrays/s", "occupancy ms", "DDA ms", "ratio",
         "Mvisits/s DDA", "TSDF ms", "Open3D ms", "ratio", "step us", "pybullet us", "ratio"],
        [[r["area"],
          f"{r['render']['stage_ms_per_frame']:.2f}", f"{r['render']['limit_ms_per_frame']:.2f}",
          f"{r['render']['ratio']:.2f}", f"{r['render']['limit_rays_per_s'] / 1e6:.1f}",
          f"{r['occupancy']['stage_ms_per_frame']:.2f}",
          f"{r['occupancy']['limit_ms_per_frame']:.2f}", f"{r['occupancy']['ratio']:.2f}",
          f"{r['occupancy']['limit_visits_per_s'] / 1e6:.0f}",
          f"{r['tsdf']['stage_ms_per_frame']:.2f}", f"{r['tsdf']['open3d_ms_per_frame']:.2f}",
          f"{r['tsdf']['ratio']:.2f}",
          f"{r['physics']['stage_us_per_step']:.1f}", f"{r['physics']['limit_us_per_step']:.1f}",
          f"{r['physics']['ratio']:.2f}"] for r in rows],
    )
    path = write_json("stage_limits", {
        "command": "python benchmarks/stage_limits.py " + " ".join(sys.argv[1:]),
        "planner": spec(args.planner).id, "seconds": args.seconds, "seed": args.seed,
        "repeats": args.repeats, "peak_rss_mib": peak_rss_mib(), "areas": rows,
    })
    print(f"\nwrote {path}")


if __name__ == "__main__":
    main()
