"""What an episode keeps for replay: poses, map keyframes, plans and surface snapshots, each on
its own schedule (`docs/recording.md`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from areas.area import Area
from sim.config import EpisodeConfig
from sim.heap import release_free_heap
from sim.occupancy import DirtyBoxSubscription
from sim.recording import RecordingWriter
from sim.sensing import Sensing
from sim.voxel_grid import IndexBox

_NOTHING_CHANGED = IndexBox((0, 0, 0), (0, 0, 0))


class EpisodeRecorder:
    """Writes the run's recording as it goes; `save` puts it on disk."""

    def __init__(self, area: Area, config: EpisodeConfig, planner_name: str, seed: int,
                 preset_name: str) -> None:
        self.cfg = config
        self.writer = RecordingWriter(header={
            "area": area.name, "planner": planner_name, "seed": seed, "preset": preset_name,
            "voxel_size": area.voxel_size, "grid_origin": area.bounds_min.tolist(),
            "grid_shape": list(area.grid_shape), "camera": config.camera.model_dump(),
            "pose_rate_hz": config.pose_record_hz,
        })
        self.next_pose = 0.0
        self.next_keyframe = 0.0
        self.last_keyframe: float | None = None
        self.next_surface = config.surface_snapshot_interval_s
        self._changes: DirtyBoxSubscription | None = None

    def pose(self, now: float, position: np.ndarray, yaw: float) -> None:
        """After a physics step: the true pose, at the recording's pose rate."""
        if now >= self.next_pose - 1e-9:
            self.writer.pose(now, position, yaw)
            self.next_pose += 1.0 / self.cfg.pose_record_hz

    def frame(self, stamp: float, sensing: Sensing) -> None:
        """After a camera frame: map keyframes and surface snapshots when they are due."""
        if stamp >= self.next_keyframe - 1e-9:
            self._keyframe(stamp, sensing)
            self.next_keyframe += self.cfg.keyframe_interval_s
        if stamp >= self.next_surface - 1e-9:
            # A snapshot's extraction and thinning take 100-350 MiB for a moment: freed heap
            # pages go back first, so that they do not add to its peak, and after.
            release_free_heap()
            self.writer.surface(stamp, sensing.tsdf.surface_points(),
                                self.cfg.surface_snapshot_voxel_m)
            release_free_heap()
            self.next_surface += self.cfg.surface_snapshot_interval_s

    def _keyframe(self, stamp: float, sensing: Sensing) -> None:
        occupancy = sensing.mapping.occupancy
        if self._changes is None:
            # From the first keyframe on, the map's box of changed voxels bounds what the next
            # keyframe compares: a keyframe then costs what changed, not the grid (5 M voxels
            # on FACILITY C, every 2 s).
            self.writer.map_keyframe(stamp, occupancy.state)
            self._changes = occupancy.subscribe()
        else:
            self.writer.map_keyframe(stamp, occupancy.state,
                                     self._changes.take() or _NOTHING_CHANGED)
        self.last_keyframe = stamp

    def finish(self, now: float, sensing: Sensing) -> None:
        """At the end of the run: a last map keyframe, unless one was just written, so that
        the replay ends on the map that was scored."""
        if self.last_keyframe is None or now > self.last_keyframe + 1e-9:
            self._keyframe(now, sensing)

    def plan(self, now: float, waypoints: np.ndarray) -> None:
        self.writer.plan(now, waypoints)

    def save(self, path: Path) -> None:
        self.writer.save(path)

    def close(self) -> None:
        """Let go of the recording's temporary files (after `save`, if it is kept)."""
        self.writer.close()
