"""Sensing and fusion: what the camera sees at each frame and what the maps make of it.

The camera runs at its rate; a preset decides which frames are fused into the occupancy map and
which into the TSDF (`EpisodeConfig.occupancy_every_n_frames`, `tsdf_every_n_frames`). Depth
noise and odometry drift come from their own random streams, so that switching one off leaves
the others alone.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from areas.area import Area
from sim.camera import DepthCamera
from sim.config import EpisodeConfig
from sim.geometry import Pose
from sim.map_view import MappingStack
from sim.noise import OdometryDrift, add_depth_noise
from sim.stage_costs import StageCosts
from sim.tsdf import TsdfVolume


@dataclass
class RandomStreams:
    """Independent random streams of one run, spawned from its seed."""

    depth: np.random.Generator
    odometry: np.random.Generator
    planner: np.random.Generator

    @classmethod
    def from_seed(cls, seed: int) -> RandomStreams:
        depth, odometry, planner = (np.random.default_rng(s) for s in
                                    np.random.SeedSequence(seed).spawn(3))
        return cls(depth, odometry, planner)


class Sensing:
    """The depth camera, the odometry estimate and the maps it feeds (occupancy, TSDF)."""

    def __init__(self, area: Area, config: EpisodeConfig, streams: RandomStreams,
                 costs: StageCosts, expected_tsdf_blocks: int = 0) -> None:
        self.cfg, self.costs = config, costs
        cam = config.camera
        self.camera = DepthCamera(area.vertices, area.triangles, cam)
        self.mapping = MappingStack(area.bounds_min, area.grid_shape, area.voxel_size,
                                    config.safety_radius_m, config.occupancy)
        self.tsdf = TsdfVolume(cam.intrinsic_matrix(), cam.max_range_m, config.tsdf,
                               expected_tsdf_blocks)
        self.drift = OdometryDrift(config.odometry_noise, streams.odometry)
        self._depth_rng = streams.depth
        self.frame_index = 0
        self.occupancy_updates = 0  # frames fused into the occupancy map so far
        # The last full-resolution frame (H, W) metres, as fused (noise included); NaN before.
        self.last_depth = np.full((config.camera.height, config.camera.width), np.nan,
                                  dtype=np.float32)

    def estimate(self, true_pose: Pose) -> Pose:
        """The pose as odometry reports it (the map frame)."""
        return self.drift.estimate(true_pose)

    def frame(self, stamp: float, true_pose: Pose) -> None:
        """One camera frame at `stamp`: render and fuse it where the preset asks for it."""
        cfg, costs = self.cfg, self.costs
        i = self.frame_index
        self.frame_index += 1
        self.drift.step()
        fuse_occ = i % cfg.occupancy_every_n_frames == 0
        fuse_tsdf = i % cfg.tsdf_every_n_frames == 0
        if not (fuse_occ or fuse_tsdf):
            return
        costs.frames += 1
        t0 = time.perf_counter()
        # A frame only the occupancy map uses is rendered at its pixel stride.
        s = cfg.occupancy_pixel_stride
        stride = 1 if fuse_tsdf else s
        rendered = self.camera.render(true_pose, stamp, stride)
        depth = add_depth_noise(rendered.depth, cfg.depth_noise, self._depth_rng)
        estimate = self.drift.estimate(true_pose)
        t1 = time.perf_counter()
        costs.render += t1 - t0
        occ_depth = depth[::s, ::s] if stride == 1 and s > 1 else depth
        ends, hit = self.camera.back_project(occ_depth, estimate, s)
        if fuse_occ:
            self.mapping.occupancy.integrate(estimate.position, ends, hit)
            self.occupancy_updates += 1
        if fuse_tsdf:
            # The surface layers count the frames the TSDF fuses (`sim/surface.py`).
            self.mapping.surface.observe(estimate.position, ends[hit])
        t2 = time.perf_counter()
        costs.occupancy += t2 - t1
        if fuse_tsdf:
            self.last_depth = depth
            self._fuse_tsdf(depth, estimate)
            costs.tsdf += time.perf_counter() - t2

    def _fuse_tsdf(self, depth: np.ndarray, estimate: Pose) -> None:
        try:
            self.tsdf.integrate(depth, estimate)
        except RuntimeError as exc:
            # A frame with no return within range (open space) has nothing to fuse, and
            # Open3D refuses it instead of doing nothing.
            if "No block is touched" not in str(exc):
                raise

    def clear_start_sphere(self, centre: np.ndarray, voxel_size: float) -> None:
        """The space around the start is known free, as a vehicle is placed in a clear spot
        before take-off: rays from the centre carve a sphere of `start_free_radius_m`, never
        closer than a voxel to a real surface. Without it the level camera's blind cones above
        and below the vehicle would leave no traversable way out of the start."""
        clearance = self.camera.distance_to_surface(centre)
        r = min(self.cfg.start_free_radius_m, clearance - voxel_size)
        if r <= 0:
            return
        n = 400
        k = np.arange(n) + 0.5
        phi = np.arccos(1.0 - 2.0 * k / n)
        theta = np.pi * (1.0 + 5**0.5) * k
        dirs = np.stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], 1)
        self.mapping.occupancy.integrate(centre, centre + r * dirs, np.zeros(n, dtype=bool))
