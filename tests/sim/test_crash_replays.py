"""Flights that collided with a part the map did not hold, replayed into today's map.

The poses of each flight (`tests/data/crash_flights`) are rendered again at the default preset's
occupancy rate and stride, with depth noise, and fused into an occupancy map at the true poses
(odometry drift would only move where the part lands in the map frame, not what the rays do to
it); the voxel holding the scene point the vehicle touched must be occupied from the first
return in it to the contact, which must come long before the contact.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from areas import load_area
from sim.camera import CameraConfig, DepthCamera
from sim.config import preset
from sim.geometry import Pose
from sim.noise import add_depth_noise
from sim.occupancy import OccupancyMap, VoxelState
from sim.open3d_any import o3d

pytestmark = pytest.mark.slow

FLIGHTS = Path(__file__).resolve().parent.parent / "data" / "crash_flights"
# Recorded poses are 10 Hz; the default preset fuses the occupancy map at 5 Hz.
EVERY = 2


# Per flight: its area, and the part it hit as a vertical segment (x, y, z0, z1), metres.
CRASHES = [
    # A 2 cm lamp rod (`areas/warehouse.py`), first returned on 37 s before the contact.
    ("warehouse", "warehouse-nbvp-v1-s0.npz", (19.5, 12.5, 9.5, 10.5), 30.0),
]


@pytest.mark.parametrize(("area_name", "flight", "part", "warning_s"), CRASHES)
def test_the_part_hit_is_held_until_the_contact(
        area_name: str, flight: str, part: tuple[float, float, float, float],
        warning_s: float) -> None:
    area = load_area(area_name)
    data = np.load(FLIGHTS / flight)
    times, poses = data["times"], data["poses"]
    cfg = preset("default")
    camera = DepthCamera(area.vertices, area.triangles, CameraConfig())
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(area.vertices.astype(np.float32)),
                        o3d.core.Tensor(area.triangles.astype(np.uint32)))
    last = poses[-1, :3].astype(np.float32)[None]
    touched = scene.compute_closest_points(o3d.core.Tensor(last))["points"].numpy()[0]
    # The flight ended in contact: the vehicle's radius from the scene.
    gap = float(np.linalg.norm(touched - poses[-1, :3]))
    assert gap <= cfg.limits.radius_m + 0.02, gap
    x, y, z0, z1 = part
    assert np.hypot(touched[0] - x, touched[1] - y) < 0.02 and z0 <= touched[2] <= z1, touched
    m = OccupancyMap(area.bounds_min, area.grid_shape, area.voxel_size, cfg.occupancy)
    voxel = tuple(int(i) for i in m.world_to_index(touched))
    rng = np.random.default_rng(0)
    first_return = None
    stride = cfg.occupancy_pixel_stride
    for n in range(0, len(times), EVERY):
        pose = Pose(poses[n, :3].astype(np.float64), float(poses[n, 3]))
        depth = add_depth_noise(camera.render(pose, stride=stride).depth, cfg.depth_noise, rng)
        ends, hit = camera.back_project(depth, pose, stride)
        m.integrate(pose.position, ends, hit)
        if first_return is None and m.returns([voxel])[1][0] > 0:
            first_return = float(times[n])
        if first_return is not None:
            assert m.state[voxel] == VoxelState.OCCUPIED, (float(times[n]), first_return)
    # Seen well before the contact, so a plan would have been kept off it.
    assert first_return is not None and first_return <= times[-1] - warning_s, first_return
