"""Drawing one run at time t into one browser tab's scene.

Each layer remembers the key of what it last sent (a keyframe index, a pose index, ...): moving
the slider re-sends only the layers whose content changed, so playback at a few updates per
second sends little more than the vehicle pose most of the time.
"""

from __future__ import annotations

from concurrent.futures import Future
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from sim.camera import BODY_FROM_OPTICAL
from sim.geometry import yaw_matrix
from web.replay.extras import Extras
from web.replay.source import RunData

RGB = tuple[int, int, int]
AREA_COLOUR: RGB = (175, 180, 190)
TRUTH_COLOUR: RGB = (90, 200, 120)
SURFACE_COLOUR: RGB = (250, 170, 60)
FRONTIER_COLOUR: RGB = (230, 40, 200)
PLAN_COLOUR: RGB = (230, 30, 30)
# Occupied voxels are shaded by height, from LOW to HIGH, so walls and floors read apart.
OCCUPIED_LOW = np.array([40, 70, 140], dtype=np.float64)
OCCUPIED_HIGH = np.array([150, 210, 255], dtype=np.float64)
# float16 positions (half the bytes) are accurate to 1.6 cm within 32 m of the area centre.
FLOAT16_REACH_M = 32.0


@dataclass
class Layers:
    """Which layers a tab shows; the GUI's checkboxes write these."""

    area_mesh: bool = True
    area_opacity: float = 0.25
    truth: bool = False
    occupied: bool = True
    frontiers: bool = True
    trajectory: bool = True
    plan: bool = True
    surface: bool = True
    final_mesh: bool = True
    clip_z: float = float("inf")  # map layers and the final mesh are cut above this height


def wxyz_from_matrix(r: npt.NDArray[np.float64]) -> tuple[float, float, float, float]:
    """Unit quaternion (w, x, y, z) of a rotation matrix (3, 3)."""
    from viser import transforms  # viser loads only once a viewer starts

    q = transforms.SO3.from_matrix(r).wxyz
    return (float(q[0]), float(q[1]), float(q[2]), float(q[3]))


def height_colours(points: npt.NDArray[np.float32], z_min: float, z_max: float
                   ) -> npt.NDArray[np.uint8]:
    """(N, 3) colours of points (N, 3) by their height between z_min and z_max."""
    frac = np.clip((points[:, 2] - z_min) / max(z_max - z_min, 1e-6), 0.0, 1.0)[:, None]
    return np.round(OCCUPIED_LOW * (1.0 - frac) + OCCUPIED_HIGH * frac).astype(np.uint8)


def polyline_segments(points: npt.NDArray[np.floating]) -> npt.NDArray[np.float32]:
    """(N - 1, 2, 3) segments joining consecutive points (N, 3)."""
    p = np.asarray(points, dtype=np.float32)
    return np.stack([p[:-1], p[1:]], axis=1)


class RunScene:
    """One run drawn under a scene-tree prefix. The primary run draws everything; a compared
    run draws only its vehicle, trajectory and plan, in its own colour."""

    def __init__(self, scene: Any, run: RunData, prefix: str, colour: RGB, *,
                 primary: bool, extras: Future[Extras] | None = None) -> None:
        self.scene, self.run, self.prefix, self.colour = scene, run, prefix, colour
        self.primary = primary
        self.extras = extras
        self._sent: dict[str, object] = {}
        self._handles: dict[str, Any] = {}
        area = run.area
        self.centre = ((area.bounds_min + area.bounds_max) / 2.0).astype(np.float64)
        reach = float(np.max(area.bounds_max - area.bounds_min)) / 2.0
        self.precision = "float16" if reach < FLOAT16_REACH_M else "float32"
        self.z_range = (float(area.bounds_min[2]), float(area.bounds_max[2]))
        self.counts: dict[str, int] = {"occupied": 0, "frontiers": 0, "surface": 0}

    # -- bookkeeping ---------------------------------------------------------------------------
    def _name(self, layer: str) -> str:
        return f"{self.prefix}/{layer}"

    def _remove(self, layer: str) -> None:
        handle = self._handles.pop(layer, None)
        if handle is not None:
            handle.remove()
        self._sent.pop(layer, None)

    def _changed(self, layer: str, key: object) -> bool:
        if layer in self._sent and self._sent[layer] == key:
            return False
        self._sent[layer] = key
        return True

    def clear(self) -> None:
        for layer in list(self._handles):
            self._remove(layer)

    def _points(self, layer: str, points: npt.NDArray[np.float32],
                colours: npt.NDArray[np.uint8] | RGB, size: float, clip_z: float) -> None:
        below = points[:, 2] <= clip_z
        points = points[below]
        if not isinstance(colours, tuple):
            colours = colours[below]
        if len(points) == 0:  # nothing to draw, but remember that this key is drawn
            handle = self._handles.pop(layer, None)
            if handle is not None:
                handle.remove()
            return
        self._handles[layer] = self.scene.add_point_cloud(
            self._name(layer), (points - self.centre).astype(np.float32), colours,
            point_size=size, point_shape="square", precision=self.precision,
            position=tuple(self.centre))

    # -- layers --------------------------------------------------------------------------------
    def show(self, time: float, layers: Layers) -> None:
        """Bring every layer to time `time`; only what changed is sent."""
        self._static(layers)
        self._vehicle(time)
        self._trajectory(time, layers.trajectory)
        self._plan(time, layers.plan)
        if self.primary:
            self._map(time, layers)
            self._surface(time, layers)

    def _static(self, layers: Layers) -> None:
        if not self.primary:
            return
        area = self.run.area
        if self._changed("area", (layers.area_mesh, layers.area_opacity)):
            self._handles["area"] = self.scene.add_mesh_simple(
                self._name("area"), area.vertices.astype(np.float32),
                area.triangles.astype(np.uint32), color=AREA_COLOUR,
                opacity=float(layers.area_opacity), side="double", flat_shading=True,
                visible=layers.area_mesh, cast_shadow=False, receive_shadow=False)
        extras = self._ready_extras()
        if layers.truth and extras is not None:
            if self._changed("truth", layers.clip_z):
                self._points("truth", extras.truth_points, TRUTH_COLOUR, 0.02, layers.clip_z)
        else:
            self._remove("truth")

    def _ready_extras(self) -> Extras | None:
        if self.extras is None or not self.extras.done() or self.extras.exception() is not None:
            return None
        return self.extras.result()

    def pose_index(self, time: float) -> int:
        return int(np.searchsorted(self.run.recording.pose_times, time, side="right")) - 1

    def _vehicle(self, time: float) -> None:
        i = self.pose_index(time)
        poses = self.run.recording.poses
        if i < 0 or len(poses) == 0:
            self._remove("vehicle")
            self._remove("camera")
            return
        x, y, z, yaw = (float(v) for v in poses[i])
        position = (x, y, z)
        wxyz = wxyz_from_matrix(yaw_matrix(yaw) @ BODY_FROM_OPTICAL)
        if "vehicle" not in self._handles:
            self._handles["vehicle"] = self.scene.add_icosphere(
                self._name("vehicle"), radius=0.3, color=self.colour, opacity=0.8,
                position=position, cast_shadow=False, receive_shadow=False)
            cam = self.run.camera
            self._handles["camera"] = self.scene.add_camera_frustum(
                self._name("camera"), fov=float(np.radians(cam.fov_v_deg)),
                aspect=cam.width / cam.height, scale=0.8, color=self.colour, thickness=0.03,
                wxyz=wxyz, position=position, cast_shadow=False, receive_shadow=False)
        else:
            self._handles["vehicle"].position = position
            self._handles["camera"].position = position
            self._handles["camera"].wxyz = wxyz

    def _trajectory(self, time: float, shown: bool) -> None:
        i = self.pose_index(time)
        if not shown or i < 1:
            self._remove("trajectory")
            return
        if self._changed("trajectory", i):
            points = self.run.recording.poses[: i + 1, :3]
            self._handles["trajectory"] = self.scene.add_line_segments(
                self._name("trajectory"), polyline_segments(points), self.colour,
                thickness=3.0, thickness_units="screen")

    def _plan(self, time: float, shown: bool) -> None:
        times = self.run.recording.array("plan_times")
        k = int(np.searchsorted(times, time, side="right")) - 1
        if not shown or k < 0:
            self._remove("plan")
            return
        if self._changed("plan", k):
            waypoints = self.run.recording.plan_at(time)[:, :3]
            # The flown path starts at the pose the plan was made from.
            start = self.run.recording.poses[max(self.pose_index(float(times[k])), 0), :3]
            points = np.vstack([start[None, :], waypoints])
            if len(points) < 2:
                self._remove("plan")
                return
            colour = PLAN_COLOUR if self.primary else self.colour
            self._handles["plan"] = self.scene.add_line_segments(
                self._name("plan"), polyline_segments(points), colour, thickness=5.0,
                thickness_units="screen")

    def _map(self, time: float, layers: Layers) -> None:
        timeline = self.run.timeline
        k = timeline.keyframe_at(time)
        want_occ, want_front = layers.occupied, layers.frontiers
        redo_occ = want_occ and self._changed("occupied", (k, layers.clip_z))
        redo_front = want_front and self._changed("frontiers", (k, layers.clip_z))
        if redo_occ or redo_front:
            state = timeline.layers(k)
            self.counts["occupied"] = len(state.occupied)
            self.counts["frontiers"] = len(state.frontiers)
            size = timeline.voxel_size
            if redo_occ:
                self._points("occupied", state.occupied,
                             height_colours(state.occupied, *self.z_range), size, layers.clip_z)
            if redo_front:
                self._points("frontiers", state.frontiers, FRONTIER_COLOUR, size * 0.6,
                             layers.clip_z)
        if not want_occ:
            self._remove("occupied")
        if not want_front:
            self._remove("frontiers")

    def _surface(self, time: float, layers: Layers) -> None:
        extras = self._ready_extras()
        at_end = time >= self.run.duration - 1e-6
        final = extras.final_mesh if extras is not None else None
        if layers.final_mesh and at_end and final is not None:
            # At the end, the final mesh replaces the last surface snapshot.
            self._remove("surface")
            if self._changed("final_mesh", layers.clip_z):
                self._handles["final_mesh"] = self.scene.add_glb(
                    self._name("final_mesh"), final.glb(layers.clip_z), cast_shadow=False,
                    receive_shadow=False)
            return
        self._remove("final_mesh")
        times = self.run.recording.array("surface_times")
        k = int(np.searchsorted(times, time, side="right")) - 1
        if not layers.surface or k < 0:
            self._remove("surface")
            return
        if self._changed("surface", (k, layers.clip_z)):
            points = self.run.recording.surface_at(time)
            self.counts["surface"] = len(points)
            self._points("surface", np.asarray(points, dtype=np.float32), SURFACE_COLOUR, 0.05,
                         layers.clip_z)
