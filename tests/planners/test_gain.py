"""The view-gain evaluator against a naive ray count and a brute-force count of visible voxels."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planners.gain import GainEvaluator, RayGrid
from sim.camera import CameraConfig
from sim.occupancy import VoxelState
from tests.planners.conftest import stack_from_state

VOXEL = 0.1
SHAPE = (60, 60, 25)
CAMERA = CameraConfig()


def _state() -> np.ndarray:
    """Unknown everywhere but a free box around (3, 3, 1.25) and an occupied pillar in it."""
    state = np.zeros(SHAPE, dtype=np.uint8)
    state[15:45, 15:45, 3:22] = VoxelState.FREE
    state[38:41, 28:32, :] = VoxelState.OCCUPIED
    return state


def naive_columns(state: np.ndarray, position: np.ndarray, rays: RayGrid, step: float,
                  min_range: float, max_range: float) -> np.ndarray:
    """The same rays marched in plain Python: r^2 dr dOmega per unknown sample."""
    out = np.zeros(len(rays.azimuths))
    n_steps = math.floor((max_range - min_range) / step)
    for e in range(rays.directions.shape[0]):
        for a in range(rays.directions.shape[1]):
            d = rays.directions[e, a]
            for s in range(n_steps):
                r = min_range + (s + 0.5) * step
                idx = np.floor((position + r * d) / VOXEL).astype(int)
                if np.any(idx < 0) or np.any(idx >= np.array(SHAPE)):
                    break
                v = state[tuple(idx)]
                if v == VoxelState.OCCUPIED:
                    break
                if v == VoxelState.UNKNOWN:
                    out[a] += r * r * step * rays.solid_angles[e]
    return out


def visible_unknown_volume(state: np.ndarray, position: np.ndarray, yaw: float) -> float:
    """Brute force over voxels: unknown voxel centres inside the frustum and range whose line
    of sight crosses no occupied voxel, times the voxel volume."""
    centres = (np.argwhere(state == VoxelState.UNKNOWN) + 0.5) * VOXEL
    rel = centres - position
    c, s = math.cos(yaw), math.sin(yaw)
    fwd = rel[:, 0] * c + rel[:, 1] * s
    left = -rel[:, 0] * s + rel[:, 1] * c
    dist = np.linalg.norm(rel, axis=1)
    inside = ((fwd > 0) & (np.abs(left) <= fwd * math.tan(math.radians(CAMERA.fov_h_deg / 2)))
              & (np.abs(rel[:, 2]) <= np.hypot(fwd, left) * math.tan(
                  math.radians(CAMERA.fov_v_deg / 2)))
              & (dist <= CAMERA.max_range_m) & (dist >= CAMERA.min_range_m))
    count = 0
    occupied = state == VoxelState.OCCUPIED
    for p in centres[inside]:
        n = int(np.ceil(np.linalg.norm(p - position) / (VOXEL / 4)))
        t = np.linspace(0.0, 1.0, n + 1)[:-1]
        idx = np.floor((position + t[:, None] * (p - position)) / VOXEL).astype(int)
        if not occupied[idx[:, 0], idx[:, 1], idx[:, 2]].any():
            count += 1
    return count * VOXEL**3


@pytest.mark.parametrize("step_deg", [10.0])
def test_columns_equal_a_naive_ray_count(step_deg: float) -> None:
    state = _state()
    stack = stack_from_state(state, VOXEL, 0.3)
    gains = GainEvaluator(CAMERA, step_deg, VOXEL)
    position = np.array([3.02, 2.97, 1.21])
    got = gains.columns(stack.view(), position)
    expected = naive_columns(state, position, gains.rays, VOXEL, CAMERA.min_range_m,
                             CAMERA.max_range_m)
    np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-12)
    assert got.sum() > 0


@pytest.mark.parametrize("yaw", [0.0, 1.0, -2.5])
def test_gain_estimates_the_visible_unknown_volume(yaw: float) -> None:
    state = _state()
    stack = stack_from_state(state, VOXEL, 0.3)
    gains = GainEvaluator(CAMERA, 2.0, VOXEL / 2)
    position = np.array([3.0, 3.0, 1.25])
    estimate = gains.gain(stack.view(), position, yaw)
    exact = visible_unknown_volume(state, position, yaw)
    assert exact > 1.0
    assert estimate == pytest.approx(exact, rel=0.12)


def test_a_fully_known_map_has_no_gain_and_an_unknown_one_has_the_frustum_volume() -> None:
    free = np.full(SHAPE, VoxelState.FREE, dtype=np.uint8)
    gains = GainEvaluator(CAMERA, 5.0, VOXEL)
    position = np.array([3.0, 3.0, 1.25])
    assert gains.best_view(stack_from_state(free, VOXEL, 0.3).view(), position).gain == 0.0
    # All unknown, in a grid tall enough for the whole frustum: the full 360-degree band of
    # the vertical field of view within range, 2 pi (r^3 / 3) (2 sin(fov_v / 2)).
    tall = np.zeros((110, 110, 110), dtype=np.uint8)
    centre = np.array([5.5, 5.5, 5.5])
    view = stack_from_state(tall, VOXEL, 0.3).view()
    total = gains.columns(view, centre).sum()
    r0, r1 = CAMERA.min_range_m, CAMERA.max_range_m
    band = 2 * math.pi * (r1**3 - r0**3) / 3 * 2 * math.sin(math.radians(CAMERA.fov_v_deg / 2))
    assert total == pytest.approx(band, rel=0.02)


def test_best_yaw_looks_at_the_unknown() -> None:
    state = np.full(SHAPE, VoxelState.FREE, dtype=np.uint8)
    state[:, 45:, :] = VoxelState.UNKNOWN  # unknown toward +y
    view = stack_from_state(state, VOXEL, 0.3).view()
    gains = GainEvaluator(CAMERA, 5.0, VOXEL)
    best = gains.best_view(view, np.array([3.0, 3.0, 1.25]))
    assert best.yaw == pytest.approx(math.pi / 2, abs=math.radians(5.1))
    assert best.gain > gains.gain(view, np.array([3.0, 3.0, 1.25]), 0.0)
    assert gains.gain(view, np.array([3.0, 3.0, 1.25]), -math.pi / 2) == 0.0
