"""Frontier voxels in the camera's view against a brute-force frustum test."""

from __future__ import annotations

import math

import numpy as np

from planners.frontiers import clusters, frontiers_in_view
from sim.camera import CameraConfig
from sim.geometry import Pose
from sim.occupancy import VoxelState
from tests.planners.conftest import stack_from_state

VOXEL = 0.1


def test_frontiers_in_view_match_a_brute_force_frustum() -> None:
    state = np.zeros((120, 120, 25), dtype=np.uint8)
    state[20:100, 20:100, 2:23] = VoxelState.FREE
    view = stack_from_state(state, VOXEL, 0.3).view()
    camera = CameraConfig()
    for yaw in (0.0, 0.7, -2.0, math.pi):
        pose = Pose(np.array([5.0, 6.0, 1.2]), yaw)
        idx, offsets = frontiers_in_view(view, pose, camera)
        rel = view.index_to_world(np.argwhere(view.frontier)) - pose.position
        yaw_rot = np.array([[math.cos(yaw), math.sin(yaw), 0], [-math.sin(yaw), math.cos(yaw), 0],
                            [0, 0, 1]])
        body = rel @ yaw_rot.T
        d = np.linalg.norm(rel, axis=1)
        fwd = body[:, 0]
        expected = ((fwd > 0) & (np.abs(body[:, 1]) <= fwd * math.tan(math.radians(45)))
                    & (np.abs(body[:, 2]) <= fwd * math.tan(math.radians(camera.fov_v_deg / 2)))
                    & (d <= camera.max_range_m) & (d >= camera.min_range_m))
        want = {tuple(v) for v in np.argwhere(view.frontier)[expected]}
        assert {tuple(v) for v in idx} == want
        assert len(want) > 0
        np.testing.assert_allclose(offsets, view.index_to_world(idx) - pose.position)


def test_clusters_carry_centroid_and_normal() -> None:
    state = np.zeros((40, 40, 20), dtype=np.uint8)
    state[:20, :, :] = VoxelState.FREE  # known free for x < 2 m, unknown beyond
    view = stack_from_state(state, VOXEL, 0.3).view()
    found = clusters(view, 10)
    assert found
    for c in found:
        assert c.normal[0] > 0.99  # pointing into the unknown, +x
        assert abs(c.centroid[0] - 1.95) < 1e-9


def test_small_frontier_groups_are_left_out() -> None:
    state = np.zeros((120, 120, 25), dtype=np.uint8)
    state[20:100, 20:100, 2:23] = VoxelState.FREE
    # An isolated unknown voxel inside the known box makes six lone frontier voxels.
    state[70, 60, 12] = VoxelState.UNKNOWN
    view = stack_from_state(state, VOXEL, 0.3).view()
    pose = Pose(np.array([5.0, 6.0, 1.2]), 0.0)
    every, _ = frontiers_in_view(view, pose, CameraConfig())
    grouped, _ = frontiers_in_view(view, pose, CameraConfig(), min_group_size=10)
    lone = {(69, 60, 12), (71, 60, 12), (70, 59, 12), (70, 61, 12), (70, 60, 11), (70, 60, 13)}
    assert lone <= {tuple(v) for v in every}
    assert {tuple(v) for v in grouped} == {tuple(v) for v in every} - lone
