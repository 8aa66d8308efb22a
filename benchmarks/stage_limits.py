"""The simulation's stages against their limits on this machine, one thread, per area.

    nice -n 10 .venv/bin/python benchmarks/stage_limits.py [--areas all] [--seconds 60]

Per area, Classic flies `--seconds` at the default preset (planning charge off, so the flight is
repeatable) and reports what each stage cost per fused camera frame in the run. The flight's
poses are then replayed through each stage alone, and through its bare limit:

- render (`DepthCamera.render` and the depth noise): Embree ray casting
  (`RaycastingScene.cast_rays`) of the frames as the preset renders
  them (every other fused frame at 160 x 120, the others at 80 x 60 rays), rays per second;
- occupancy: the 3D-DDA walk alone (`sim.occupancy_kernels._traverse`) against the update that
  walks and updates (`OccupancyMap.integrate`), ray-voxel visits per second;
- TSDF: Open3D's integration of each full frame (`TsdfVolume.integrate`), ms per frame;
- physics: one `World.step` (control, pybullet step, contact query) against a bare
  `pybullet.stepSimulation` of the same world, microseconds per step.

"limit" is each stage's cost per fused frame at its bare rate on the frames of that flight,
"alone" the stage's own cost on the same frames (CPU time of the process), and the run's wall
time per stage is given beside them. Threads are limited to one before the
libraries load (`worker.threads`).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from worker.threads import thread_environment

os.environ.update(thread_environment(1, os.environ))

import numba
import numpy as np
import numpy.typing as npt

from areas import area_names, load_area, load_ground_truth
from benchmarks.common import peak_rss_mib, print_table, write_json
from planners.registry import make
from sim.camera import DepthCamera
from sim.config import EpisodeConfig, preset
from sim.episode import run_episode
from sim.geometry import Pose
from sim.noise import add_depth_noise
from sim.occupancy import OccupancyMap
from sim.occupancy_kernels import _traverse
from sim.open3d_any import o3d
from sim.recording import Recording
from sim.trajectory import TrajectorySample
from sim.tsdf import TsdfVolume
from sim.world import World

# CPU time of the process (all its threads): one thread per library, so about the wall time on
# an idle core, and far less moved by other work on the machine than the wall clock.
clock = time.process_time


@numba.njit(cache=True)
def _walk(origin: npt.NDArray[np.float64], ends: npt.NDArray[np.float64],
          grid_origin: npt.NDArray[np.float64], voxel_size: float,
          shape: tuple[int, int, int]) -> int:
    """The 3D-DDA walk of every ray through the grid, nothing updated: voxels visited."""
    nx, ny, nz = shape
    buf = np.empty(nx + ny + nz + 3, dtype=np.int64)
    ax = (origin[0] - grid_origin[0]) / voxel_size
    ay = (origin[1] - grid_origin[1]) / voxel_size
    az = (origin[2] - grid_origin[2]) / voxel_size
    visits = 0
    for r in range(ends.shape[0]):
        bx = (ends[r, 0] - grid_origin[0]) / voxel_size
        by = (ends[r, 1] - grid_origin[1]) / voxel_size
        bz = (ends[r, 2] - grid_origin[2]) / voxel_size
        visits += _traverse(ax, ay, az, bx, by, bz, nx, ny, nz, buf)[0]
    return visits


def fly(area_name: str, config: EpisodeConfig, seconds: float) -> tuple[
    dict[str, float], npt.NDArray[np.float32]
]:
    """Classic's flight: its per-frame stage costs and its poses (T, 4) at the fused rate."""
    area = load_area(area_name)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "run.npz"
        result = run_episode(area, load_ground_truth(area), make("classic"), config, 0,
                             seconds=seconds, recording_path=path)
        poses = Recording(path).poses
    rate = config.camera.rate_hz / config.occupancy_every_n_frames
    return result.frame_costs_ms, poses[::max(round(config.pose_record_hz / rate), 1)]


def replay_sensing(area_name: str, config: EpisodeConfig,
                   poses: npt.NDArray[np.float32]) -> dict[str, float]:
    """The fused frames of `poses` through ray casting, the DDA walk, the occupancy update and
    the TSDF, each timed alone; rates and totals."""
    area = load_area(area_name)
    camera = DepthCamera(area.vertices, area.triangles, config.camera)
    occupancy = OccupancyMap(area.bounds_min, area.grid_shape, area.voxel_size, config.occupancy)
    tsdf = TsdfVolume(config.camera.intrinsic_matrix(), config.camera.max_range_m, config.tsdf)
    rng = np.random.default_rng(0)
    stride = config.occupancy_pixel_stride
    every_tsdf = config.tsdf_every_n_frames // config.occupancy_every_n_frames
    out = {"rays": 0.0, "cast_s": 0.0, "render_s": 0.0, "visits": 0.0, "walk_s": 0.0,
           "update_s": 0.0, "tsdf_frames": 0.0, "tsdf_s": 0.0}
    grid_origin = np.ascontiguousarray(occupancy.origin)
    # Untimed: the first cast builds Embree's scene, the first walk loads the kernel.
    first = Pose(poses[0, :3].astype(np.float64), float(poses[0, 3]))
    ends, _ = camera.back_project(camera.render(first, stride=stride).depth, first, stride)
    _walk(first.position, ends, grid_origin, area.voxel_size, area.grid_shape)
    for i, p in enumerate(poses):
        pose = Pose(p[:3].astype(np.float64), float(p[3]))
        full = i % every_tsdf == 0
        s = 1 if full else stride
        dirs = camera._unit_directions(s) @ camera.world_from_optical(pose.yaw).T
        rays = np.empty((len(dirs), 6), dtype=np.float32)
        rays[:, :3], rays[:, 3:] = pose.position, dirs
        tensor = o3d.core.Tensor(rays)
        t0 = clock()
        camera._scene.cast_rays(tensor)
        out["cast_s"] += clock() - t0
        out["rays"] += len(rays)
        t0 = clock()
        depth = add_depth_noise(camera.render(pose, stride=s).depth, config.depth_noise, rng)
        out["render_s"] += clock() - t0
        occ_depth = depth[::stride, ::stride] if full else depth
        ends, hit = camera.back_project(occ_depth, pose, stride)
        t0 = clock()
        out["visits"] += _walk(pose.position, ends, grid_origin, area.voxel_size,
                               area.grid_shape)
        t1 = clock()
        occupancy.integrate(pose.position, ends, hit)
        t2 = clock()
        out["walk_s"] += t1 - t0
        out["update_s"] += t2 - t1
        if full:
            t0 = clock()
            tsdf.integrate(depth, pose)
            out["tsdf_s"] += clock() - t0
            out["tsdf_frames"] += 1
    return out


def replay_physics(area_name: str, config: EpisodeConfig, steps: int) -> dict[str, float]:
    """Hovering at the start: `World.step` against a bare pybullet step, seconds per step."""
    import pybullet

    area = load_area(area_name)
    world = World(area.vertices, area.triangles, area.start.position, config.limits,
                  config.physics)
    try:
        hold = TrajectorySample(area.start.position.copy(), np.zeros(3), np.zeros(3), 0.0, 0.0)
        t0 = clock()
        for _ in range(steps):
            world.step(hold)
        step_s = (clock() - t0) / steps
        t0 = clock()
        for _ in range(steps):
            pybullet.stepSimulation(physicsClientId=world._client)
        bare_s = (clock() - t0) / steps
    finally:
        world.close()
    return {"step_s": step_s, "bare_step_s": bare_s}


def measure(area_name: str, seconds: float, physics_steps: int) -> dict[str, Any]:
    config = preset("default").model_copy(update={"planning_time_charge": "none"})
    costs, poses = fly(area_name, config, seconds)
    sensing = replay_sensing(area_name, config, poses)
    physics = replay_physics(area_name, config, physics_steps)
    frames = len(poses)
    steps_per_frame = config.physics.rate_hz / (config.camera.rate_hz
                                               / config.occupancy_every_n_frames)
    rates = {
        "rays_per_s": sensing["rays"] / sensing["cast_s"],
        "walk_visits_per_s": sensing["visits"] / sensing["walk_s"],
        "update_visits_per_s": sensing["visits"] / sensing["update_s"],
        "tsdf_ms_per_frame": 1000.0 * sensing["tsdf_s"] / max(sensing["tsdf_frames"], 1),
        "step_us": 1e6 * physics["step_s"], "bare_step_us": 1e6 * physics["bare_step_s"],
        "rays_per_frame": sensing["rays"] / frames, "visits_per_frame": sensing["visits"] / frames,
    }
    alone = {  # ms per fused frame, each stage alone on the same frames
        "render": 1000.0 * sensing["render_s"] / frames,
        "occupancy": 1000.0 * sensing["update_s"] / frames,
        "tsdf": 1000.0 * sensing["tsdf_s"] / frames,
        "physics": 1000.0 * physics["step_s"] * steps_per_frame,
    }
    limits = {  # ms per fused frame at the bare rate
        "render": 1000.0 * sensing["cast_s"] / frames,
        "occupancy": 1000.0 * sensing["walk_s"] / frames,
        "tsdf": 1000.0 * sensing["tsdf_s"] / frames,
        "physics": 1000.0 * physics["bare_step_s"] * steps_per_frame,
    }
    return {"area": area_name, "seconds": seconds, "fused_frames": frames, "rates": rates,
            "run_ms": {k: costs[k] for k in limits}, "alone_ms": alone, "limit_ms": limits}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--areas", nargs="+", default=["all"])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--physics-steps", type=int, default=2000)
    parser.add_argument("--out", default="stage_limits")
    args = parser.parse_args()
    names = area_names() if args.areas == ["all"] else args.areas
    warm = load_area("maze")
    run_episode(warm, load_ground_truth(warm), make("classic"), preset("exact"), 0, seconds=5.0)
    rows = []
    for name in names:
        rows.append(measure(name, args.seconds, args.physics_steps))
        print(f"{name} measured", flush=True)
    print_table(
        "Bare rates, one thread", ["area", "cast rays/s", "DDA walk visits/s",
                                   "DDA update visits/s", "visits/frame", "TSDF ms/frame",
                                   "World.step us", "pybullet step us"],
        [[r["area"], f"{r['rates']['rays_per_s']:,.0f}",
          f"{r['rates']['walk_visits_per_s']:,.0f}", f"{r['rates']['update_visits_per_s']:,.0f}",
          f"{r['rates']['visits_per_frame']:,.0f}", f"{r['rates']['tsdf_ms_per_frame']:.2f}",
          f"{r['rates']['step_us']:.1f}", f"{r['rates']['bare_step_us']:.1f}"] for r in rows])
    stages = ("render", "occupancy", "tsdf", "physics")
    print_table(
        "Per fused frame of Classic's flight, ms of CPU: each stage alone against its limit",
        ["area", *(f"{s} alone / limit" for s in stages)],
        [[r["area"], *(f"{r['alone_ms'][s]:.2f} / {r['limit_ms'][s]:.2f} "
                       f"({r['alone_ms'][s] / r['limit_ms'][s]:.1f}x)" for s in stages)]
         for r in rows])
    print_table(
        f"The same stages in the run ({args.seconds:g} s), ms of wall time per fused frame",
        ["area", *stages], [[r["area"], *(f"{r['run_ms'][s]:.2f}" for s in stages)]
                            for r in rows])
    path = write_json(args.out, {
        "command": "python benchmarks/stage_limits.py " + " ".join(sys.argv[1:]),
        "seconds": args.seconds, "peak_rss_mib": peak_rss_mib(), "areas": rows,
    })
    print(f"\nwrote {path}")


if __name__ == "__main__":
    main()
