"""Simulation speed of MAZE + Classic, the per-frame cost breakdown, and the mapping fidelity of
the default preset against fusing every frame at full resolution.

    .venv/bin/python benchmarks/sim_speed.py [--seconds 700] [--seed 0]

Speed: one episode at the default preset in this process (one core), simulated seconds per wall
second. Fidelity: the flight's camera poses (20 Hz) are replayed into two occupancy maps, one
fused as the default preset does and one with every frame at full resolution, with the same
noise model; the explored volumes at the plateau are compared. Replaying one flight isolates the
integration scheme from the planner's different choices on a different map.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from areas import load_area, load_ground_truth
from benchmarks.common import peak_rss_mib, print_table, write_json
from planners.registry import make, spec
from sim.camera import DepthCamera
from sim.config import EpisodeConfig, preset
from sim.episode import run_episode
from sim.geometry import Pose
from sim.noise import OdometryDrift, add_depth_noise
from sim.occupancy import OccupancyMap
from sim.recording import Recording

# The newest original Classic, named by its id in the results.
CLASSIC = spec("classic").id


def replay_volume(area_name: str, poses: np.ndarray, config: EpisodeConfig, every: int,
                  stride: int, seed: int) -> tuple[float, float]:
    """Explored volume and coverage after fusing every `every`-th of the 20 Hz `poses` (T, 4)
    with rays of every `stride`-th row and column."""
    area = load_area(area_name)
    camera = DepthCamera(area.vertices, area.triangles, config.camera)
    occupancy = OccupancyMap(area.bounds_min, area.grid_shape, area.voxel_size, config.occupancy)
    rng = np.random.default_rng(seed)
    drift = OdometryDrift(config.odometry_noise, np.random.default_rng(seed + 1))
    for i, p in enumerate(poses):
        drift.step()
        if i % every:
            continue
        pose = Pose(p[:3].astype(np.float64), float(p[3]))
        depth = add_depth_noise(camera.render(pose, stride=stride).depth, config.depth_noise, rng)
        estimate = drift.estimate(pose)
        ends, hit = camera.back_project(depth, estimate, stride)
        occupancy.integrate(estimate.position, ends, hit)
    observable = load_ground_truth(area).observable
    known = np.count_nonzero((occupancy.state != 0) & observable)
    return occupancy.explored_volume_m3, known / np.count_nonzero(observable)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=700.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--no-replay", action="store_true", help="measure speed only")
    args = parser.parse_args()
    area = load_area("maze")
    truth = load_ground_truth(area)
    config = preset("default").model_copy(update={"pose_record_hz": 20.0})
    recording = Path(__file__).resolve().parent / "results" / "sim_speed_recording.npz"
    recording.parent.mkdir(parents=True, exist_ok=True)
    # A short episode first loads (or, after an edit, compiles) the numba kernels, a one-off
    # cost per installation that is not the simulation's speed.
    run_episode(area, truth, make(CLASSIC), config, args.seed, seconds=5.0)
    started = time.perf_counter()
    result = run_episode(area, truth, make(CLASSIC), config, args.seed,
                         planner_name=CLASSIC, preset_name="default",
                         seconds=args.seconds, recording_path=recording)
    wall = time.perf_counter() - started
    simulated = result.simulated_until
    costs = result.frame_costs_ms
    every = min(config.occupancy_every_n_frames, config.tsdf_every_n_frames)
    fused_rate = config.camera.rate_hz / every
    per_frame_total = sum(costs.values())
    print_table(
        f"MAZE + Classic, default preset, seed {args.seed}: {simulated:.0f} simulated s "
        f"in {wall:.1f} wall s",
        ["quantity", "value"],
        [
            ["simulated s per wall s", f"{simulated / wall:.1f}"],
            ["fused frames per simulated s", f"{fused_rate:g}"],
            ["status", f"{result.status.value} ({result.reason})"],
            ["coverage", f"{result.coverage:.3f}"],
            ["explored volume m³", f"{result.explored_volume_m3:.1f}"],
            ["peak resident memory MiB", f"{peak_rss_mib():.0f}"],
            ["iterations", result.iterations],
            ["planning time mean / max ms",
             f"{np.mean(result.planning_times_ms):.1f} / {np.max(result.planning_times_ms):.1f}"],
        ],
    )
    print_table("Cost per rendered (fused) camera frame, ms", ["stage", "ms", "share"],
                [[k, f"{v:.2f}", f"{v / per_frame_total:.0%}"] for k, v in costs.items()])

    fidelity = {}
    if not args.no_replay:
        fidelity = compare_fusion(recording, simulated, config, args.seed)
    path = write_json("sim_speed_no_replay" if args.no_replay else "sim_speed", {
        "command": "python benchmarks/sim_speed.py " + " ".join(sys.argv[1:]),
        "area": "maze", "planner": CLASSIC, "preset": "default", "seed": args.seed,
        "simulated_s": simulated, "wall_s": wall, "realtime_factor": simulated / wall,
        "peak_rss_mib": peak_rss_mib(), "frame_costs_ms": costs,
        "coverage": result.coverage, "status": result.status.value,
        "fidelity": fidelity,
    })
    print(f"\nwrote {path}")


def compare_fusion(recording: Path, simulated: float, config: EpisodeConfig,
                   seed: int) -> dict[str, dict[str, float]]:
    """Replay the recorded flight with several fusion schemes; print and return the volumes."""
    rec = Recording(recording)
    poses = rec.poses[rec.pose_times <= simulated + 1e-6]
    schemes = {
        f"default ({20 // config.occupancy_every_n_frames} Hz, "
        f"{160 // config.occupancy_pixel_stride}x{120 // config.occupancy_pixel_stride} rays)": (
            config.occupancy_every_n_frames, config.occupancy_pixel_stride),
        "10 Hz, 80x60 rays": (2, 2),
        "5 Hz, 160x120 rays": (4, 1),
        "full (20 Hz, 160x120 rays)": (1, 1),
    }
    fidelity = {}
    for name, (every, stride) in schemes.items():
        t0 = time.perf_counter()
        volume, cov = replay_volume("maze", poses, config, every, stride, seed)
        fidelity[name] = {"explored_volume_m3": volume, "coverage": cov,
                          "wall_s": time.perf_counter() - t0}
    full = fidelity["full (20 Hz, 160x120 rays)"]["explored_volume_m3"]
    print_table(
        f"Explored volume after replaying the same flight ({len(poses)} frames at 20 Hz)",
        ["fusion", "volume m³", "vs full", "coverage", "replay wall s"],
        [[k, f"{v['explored_volume_m3']:.1f}", f"{v['explored_volume_m3'] / full - 1:+.2%}",
          f"{v['coverage']:.4f}", f"{v['wall_s']:.1f}"] for k, v in fidelity.items()],
    )
    return fidelity


if __name__ == "__main__":
    main()
