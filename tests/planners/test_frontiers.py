"""Frontier voxels in the camera's view against a brute-force frustum test."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import ndimage

from planners.frontiers import _grouped_voxels, clusters, frontiers_in_view
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


def _labelled_reference(frontier: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                        min_size: int) -> np.ndarray:
    """The voxels of groups of at least `min_size`, labelled in the box by SciPy."""
    sub = frontier[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]]
    labels, _ = ndimage.label(sub, structure=np.ones((3, 3, 3), dtype=bool))
    sizes = np.bincount(labels.ravel())
    sizes[0] = 0
    return np.argwhere(sizes[labels] >= min_size) + lo


@pytest.mark.parametrize("seed", range(6))
def test_frontier_groups_are_those_scipy_labels(seed: int) -> None:
    """The breadth-first grouping gives SciPy's 26-connected labelling's voxels, in the same
    (C) order, for random sparse and dense grids, boxes cut at the grid's faces, and sizes."""
    rng = np.random.default_rng(seed)
    shape = (int(rng.integers(5, 40)), int(rng.integers(5, 40)), int(rng.integers(3, 25)))
    frontier = rng.random(shape) < rng.choice([0.02, 0.1, 0.3, 0.6])
    for _ in range(10):
        lo = np.array([rng.integers(0, s) for s in shape], dtype=np.int64)
        hi = np.array([rng.integers(a + 1, s + 1) for a, s in zip(lo, shape, strict=True)],
                      dtype=np.int64)
        for min_size in (1, 2, 5, 30):
            got = _grouped_voxels(frontier, lo, hi, min_size)
            want = _labelled_reference(frontier, lo, hi, min_size)
            assert got.dtype == np.int64
            np.testing.assert_array_equal(got, want)
