"""The surface observation layers: TSDF weight and viewing sectors on the occupancy grid."""

from __future__ import annotations

import math

import numpy as np
import pytest

from areas import load_area, load_ground_truth
from planners.registry import make
from sim.config import preset
from sim.episode import run_episode
from sim.interface import Observation, Plan, PlannerContext
from sim.occupancy import OccupancyMap, VoxelState
from sim.surface import SECTORS, WEIGHT_MAX, SurfaceObservations, direction_sector

VOXEL = 0.1


def _layers() -> tuple[OccupancyMap, SurfaceObservations]:
    occupancy = OccupancyMap(np.zeros(3), (20, 20, 10), VOXEL)
    return occupancy, SurfaceObservations(occupancy)


def test_a_frame_adds_one_to_each_voxel_it_measured() -> None:
    _, surface = _layers()
    # Three returns in voxel (5, 5, 5), one in (6, 5, 5).
    points = np.array([[0.51, 0.52, 0.55], [0.55, 0.55, 0.55], [0.59, 0.51, 0.58],
                       [0.65, 0.55, 0.55]])
    camera = np.array([1.8, 0.55, 0.55])
    surface.observe(camera, points)
    surface.observe(camera, points[:1])
    assert surface.weight[5, 5, 5] == 2
    assert surface.weight[6, 5, 5] == 1
    assert int(surface.weight.sum()) == 3


def test_weight_saturates() -> None:
    _, surface = _layers()
    point = np.array([[0.55, 0.55, 0.55]])
    for _ in range(WEIGHT_MAX + 20):
        surface.observe(np.array([1.5, 0.55, 0.55]), point)
    assert surface.weight[5, 5, 5] == WEIGHT_MAX


def test_sectors_record_where_the_camera_stood() -> None:
    _, surface = _layers()
    point = np.array([[1.05, 1.05, 0.55]])
    centre = np.array([1.05, 1.05])
    seen = 0
    for sector in range(SECTORS):
        angle = (sector + 0.5) * 2.0 * math.pi / SECTORS
        camera = np.array([*(centre + 0.8 * np.array([math.cos(angle), math.sin(angle)])), 0.9])
        surface.observe(camera, point)
        seen |= 1 << sector
        assert surface.directions[10, 10, 5] == seen
    assert surface.directions[10, 10, 5] == 0xFF


def test_direction_sector_boundaries() -> None:
    dx = np.array([1.0, 1.0, 0.0, -1.0, -1.0, 0.0, 1.0, 1.0])
    dy = np.array([0.0, 1e-9, 1.0, 1e-9, -1e-9, -1.0, -1e-9, -1.0])
    np.testing.assert_array_equal(direction_sector(dx, dy), [0, 0, 2, 3, 4, 6, 7, 7])


def test_returns_outside_the_grid_or_not_finite_are_ignored() -> None:
    _, surface = _layers()
    box = surface.observe(np.zeros(3), np.array([[-0.5, 0.5, 0.5], [5.0, 0.5, 0.5],
                                                 [np.nan, 0.5, 0.5], [0.5, np.inf, 0.5]]))
    assert box is None
    assert not surface.weight.any()
    assert not surface.directions.any()


def test_changes_go_to_the_surface_subscribers_only() -> None:
    occupancy, surface = _layers()
    occupancy_sub, surface_sub = occupancy.subscribe(), surface.subscribe()
    box = surface.observe(np.array([1.5, 0.5, 0.5]),
                          np.array([[0.25, 0.35, 0.45], [0.75, 0.15, 0.05]]))
    assert box is not None
    assert (box.lo, box.hi) == ((2, 1, 0), (8, 4, 5))
    taken = surface_sub.take()
    assert taken is not None and (taken.lo, taken.hi) == (box.lo, box.hi)
    assert occupancy_sub.take() is None


def test_layers_are_read_only_views() -> None:
    _, surface = _layers()
    with pytest.raises(ValueError):
        surface.weight[0, 0, 0] = 1
    with pytest.raises(ValueError):
        surface.directions[0, 0, 0] = 1


class _Watching:
    """Classic, keeping what the map's layers held at its last call."""

    def __init__(self) -> None:
        self.inner = make("classic")
        self.calls = 0
        self.weight = np.zeros(0, dtype=np.uint8)
        self.directions = np.zeros(0, dtype=np.uint8)
        self.state = np.zeros(0, dtype=np.uint8)

    def reset(self, ctx: PlannerContext) -> None:
        self.inner.reset(ctx)

    def plan(self, obs: Observation) -> Plan:
        self.calls += 1
        self.weight = obs.map.surface_weight.copy()
        self.directions = obs.map.surface_directions.copy()
        self.state = obs.map.state.copy()
        return self.inner.plan(obs)


@pytest.mark.slow
def test_a_flight_fills_the_layers_on_the_measured_surface() -> None:
    area = load_area("maze")
    watching = _Watching()
    config = preset("exact")
    seconds = 30.0
    result = run_episode(area, load_ground_truth(area), watching, config, 0, seconds=seconds)
    assert watching.calls > 2
    weighted = watching.weight > 0
    # Every measured voxel has a sector, and only measured voxels have one.
    np.testing.assert_array_equal(weighted, watching.directions > 0)
    # No voxel was measured by more frames than the TSDF fused.
    fused = math.ceil(result.simulated_until * config.camera.rate_hz
                      / config.tsdf_every_n_frames)
    assert 0 < int(watching.weight.max()) <= fused
    # The returns lie on surfaces: most measured voxels are mapped as occupied.
    occupied = watching.state[weighted] == VoxelState.OCCUPIED
    occupied_share = np.count_nonzero(occupied) / np.count_nonzero(weighted)
    assert occupied_share > 0.7
    # Walls seen from more than one side of the room show more than one sector.
    assert np.any(np.bitwise_count(watching.directions) >= 2)


def test_layers_match_a_point_by_point_reference_with_many_points_per_voxel() -> None:
    """Each point's voxel gets one weight per frame and the sector the camera stands in as
    seen from that voxel's centre, whatever the number of points in it; the box returned is
    the box of those voxels."""
    rng = np.random.default_rng(8)
    occupancy, layers = _layers()
    weight = np.zeros(occupancy.shape, dtype=np.int64)
    directions = np.zeros(occupancy.shape, dtype=np.int64)
    for _ in range(30):
        camera = rng.uniform(-0.5, 2.5, 3)
        centres = rng.uniform(0.0, 2.0, (40, 3)) * [1.0, 1.0, 0.5]
        points = np.repeat(centres, 6, axis=0) + rng.uniform(-0.04, 0.04, (240, 3))
        box = layers.observe(camera, points)
        idx = np.floor(points / VOXEL).astype(np.int64)
        inside = np.all((idx >= 0) & (idx < occupancy.shape), axis=1)
        voxels = np.unique(idx[inside], axis=0)
        for v in voxels:
            weight[tuple(v)] = min(weight[tuple(v)] + 1, WEIGHT_MAX)
            centre = (v + 0.5) * VOXEL
            directions[tuple(v)] |= 1 << int(direction_sector(camera[0] - centre[0],
                                                              camera[1] - centre[1]))
        assert box is not None
        assert box.lo == tuple(voxels.min(axis=0)) and box.hi == tuple(voxels.max(axis=0) + 1)
    np.testing.assert_array_equal(layers.weight, weight)
    np.testing.assert_array_equal(layers.directions, directions)
