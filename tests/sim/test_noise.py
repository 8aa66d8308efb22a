"""Depth noise model and bounded odometry drift: values, statistics, seeding and the off switch."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import ValidationError

from sim.geometry import Pose
from sim.noise import (
    DepthNoiseConfig,
    OdometryDrift,
    OdometryNoiseConfig,
    add_depth_noise,
    depth_sigma,
)

DEFAULT = DepthNoiseConfig()
SIGMA_3M = 0.0012 + 0.0019 * (3.0 - 0.4) ** 2  # 0.014044


def test_depth_sigma_values() -> None:
    assert float(depth_sigma(np.array(3.0), DEFAULT)) == pytest.approx(0.014044)
    # Minimum sigma_a at z0, quadratic either side.
    assert float(depth_sigma(np.array(0.4), DEFAULT)) == pytest.approx(0.0012)
    assert float(depth_sigma(np.array(1.4), DEFAULT)) == pytest.approx(0.0012 + 0.0019)
    assert float(depth_sigma(np.array(5.0), DEFAULT)) == pytest.approx(0.0012 + 0.0019 * 4.6**2)
    custom = DepthNoiseConfig(sigma_a=0.01, sigma_b=0.1, z0=1.0)
    z = np.array([[1.0, 2.0], [3.0, 0.0]], dtype=np.float32)
    sigma = depth_sigma(z, custom)
    assert sigma.shape == (2, 2)
    assert sigma.dtype == np.float64
    assert np.allclose(sigma, [[0.01, 0.11], [0.41, 0.11]])
    assert np.isnan(depth_sigma(np.array([np.nan]), DEFAULT)[0])


def test_noise_configs_reject_negative_values() -> None:
    with pytest.raises(ValidationError):
        DepthNoiseConfig(sigma_a=-0.1)
    with pytest.raises(ValidationError):
        OdometryNoiseConfig(position_bound_m=-1.0)


def test_constant_depth_noise_statistics() -> None:
    depth = np.full((200, 200), 3.0, dtype=np.float32)
    noisy = add_depth_noise(depth, DEFAULT, np.random.default_rng(7))
    assert noisy.shape == depth.shape
    assert noisy.dtype == np.float32
    assert np.all(depth == 3.0)  # the input is not modified
    # 40 000 samples: standard error of the mean ~7e-5, of the std ~0.35 %.
    assert float(noisy.mean()) == pytest.approx(3.0, abs=3e-4)
    assert float(noisy.std()) == pytest.approx(SIGMA_3M, rel=0.03)
    # Gaussian: ~68 % within one sigma, ~95 % within two.
    within_1 = float(np.mean(np.abs(noisy - 3.0) < SIGMA_3M))
    within_2 = float(np.mean(np.abs(noisy - 3.0) < 2 * SIGMA_3M))
    assert within_1 == pytest.approx(0.6827, abs=0.01)
    assert within_2 == pytest.approx(0.9545, abs=0.01)


def test_noise_grows_with_depth() -> None:
    rng = np.random.default_rng(3)
    near = add_depth_noise(np.full((100, 100), 1.0, dtype=np.float32), DEFAULT, rng)
    far = add_depth_noise(np.full((100, 100), 4.0, dtype=np.float32), DEFAULT, rng)
    assert float(near.std()) == pytest.approx(0.0012 + 0.0019 * 0.6**2, rel=0.05)
    assert float(far.std()) == pytest.approx(0.0012 + 0.0019 * 3.6**2, rel=0.05)


def test_nan_stays_nan() -> None:
    depth = np.full((50, 60), 2.0, dtype=np.float32)
    depth[10:20, :] = np.nan
    noisy = add_depth_noise(depth, DEFAULT, np.random.default_rng(1))
    assert np.array_equal(np.isnan(noisy), np.isnan(depth))
    assert np.all(np.isfinite(noisy[~np.isnan(depth)]))
    all_nan = np.full((4, 4), np.nan, dtype=np.float32)
    assert np.all(np.isnan(add_depth_noise(all_nan, DEFAULT, np.random.default_rng(1))))


def test_noisy_depth_is_never_negative() -> None:
    config = DepthNoiseConfig(sigma_a=1.0, sigma_b=0.0)
    depth = np.full((50, 50), 0.01, dtype=np.float32)
    noisy = add_depth_noise(depth, config, np.random.default_rng(5))
    assert float(noisy.min()) == 0.0  # about half would be negative without the clamp
    assert np.count_nonzero(noisy == 0.0) > 1000
    assert np.all(noisy >= 0.0)


def test_disabled_returns_exact_input() -> None:
    depth = np.linspace(0.2, 5.0, 300, dtype=np.float32).reshape(15, 20)
    depth[3, 4] = np.nan
    out = add_depth_noise(depth, DepthNoiseConfig(enabled=False), np.random.default_rng(2))
    assert np.array_equal(out, depth, equal_nan=True)
    assert out.dtype == np.float32


def test_random_stream_does_not_depend_on_the_switch_or_the_scene() -> None:
    depth = np.full((8, 8), 2.0, dtype=np.float32)
    rng_on, rng_off, rng_nan = (np.random.default_rng(11) for _ in range(3))
    add_depth_noise(depth, DEFAULT, rng_on)
    add_depth_noise(depth, DepthNoiseConfig(enabled=False), rng_off)
    add_depth_noise(np.full((8, 8), np.nan, dtype=np.float32), DEFAULT, rng_nan)
    after = [r.random(5) for r in (rng_on, rng_off, rng_nan)]
    assert np.array_equal(after[0], after[1])
    assert np.array_equal(after[0], after[2])


def test_same_seed_same_noise() -> None:
    depth = np.full((64, 64), 3.0, dtype=np.float32)
    a = add_depth_noise(depth, DEFAULT, np.random.default_rng(42))
    b = add_depth_noise(depth, DEFAULT, np.random.default_rng(42))
    c = add_depth_noise(depth, DEFAULT, np.random.default_rng(43))
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)


def run_drift(config: OdometryNoiseConfig, seed: int, steps: int) -> tuple[np.ndarray, np.ndarray]:
    drift = OdometryDrift(config, np.random.default_rng(seed))
    offsets = np.empty((steps, 3))
    yaws = np.empty(steps)
    for i in range(steps):
        drift.step()
        offsets[i] = drift.offset
        yaws[i] = drift.yaw_offset
    return offsets, yaws


def test_odometry_drift_stays_within_bounds_and_moves() -> None:
    config = OdometryNoiseConfig()
    offsets, yaws = run_drift(config, seed=0, steps=10_000)
    assert np.all(np.abs(offsets) <= config.position_bound_m)
    assert np.all(np.abs(yaws) <= config.yaw_bound_rad)
    # A walk of 10 000 steps of 2 mm (std 0.2 m unbounded) explores its 5 cm box...
    assert np.abs(offsets).max() == pytest.approx(config.position_bound_m)
    assert np.abs(yaws).max() == pytest.approx(config.yaw_bound_rad)
    for axis in range(3):
        assert offsets[:, axis].min() < -0.8 * config.position_bound_m
        assert offsets[:, axis].max() > 0.8 * config.position_bound_m
    # ...one small step at a time.
    steps = np.abs(np.diff(offsets, axis=0))
    assert steps.max() < 6 * config.position_step_m
    assert np.abs(np.diff(yaws)).max() < 6 * config.yaw_step_rad
    assert np.count_nonzero(offsets) > 0.9 * offsets.size


def test_odometry_drift_is_seeded() -> None:
    config = OdometryNoiseConfig()
    a = run_drift(config, seed=9, steps=500)
    b = run_drift(config, seed=9, steps=500)
    c = run_drift(config, seed=10, steps=500)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    assert not np.array_equal(a[0], c[0])


def test_disabled_drift_stays_at_zero() -> None:
    rng = np.random.default_rng(4)
    drift = OdometryDrift(OdometryNoiseConfig(enabled=False), rng)
    for _ in range(1000):
        drift.step()
    assert np.array_equal(drift.offset, np.zeros(3))
    assert drift.yaw_offset == 0.0
    pose = Pose(np.array([1.0, 2.0, 3.0]), 0.5)
    estimate = drift.estimate(pose)
    assert np.array_equal(estimate.position, pose.position)
    assert estimate.yaw == 0.5
    # It still consumes 4 draws per step, like the enabled walk.
    reference = np.random.default_rng(4)
    reference.standard_normal((1000, 4))
    assert rng.random() == reference.random()


def test_estimate_adds_the_offset() -> None:
    drift = OdometryDrift(OdometryNoiseConfig(), np.random.default_rng(0))
    drift.offset = np.array([0.01, -0.02, 0.03])
    drift.yaw_offset = 0.015
    pose = Pose(np.array([1.0, 2.0, 3.0]), 0.5)
    estimate = drift.estimate(pose)
    assert estimate.position == pytest.approx([1.01, 1.98, 3.03])
    assert estimate.yaw == pytest.approx(0.515)
    assert np.array_equal(pose.position, [1.0, 2.0, 3.0])  # the true pose is untouched
    # The estimated yaw is wrapped to (-pi, pi].
    wrapped = drift.estimate(Pose(np.zeros(3), np.pi - 0.005))
    assert wrapped.yaw == pytest.approx(-np.pi + 0.01)
    # After stepping, the estimate follows the walk.
    drift.step()
    stepped = drift.estimate(pose)
    assert stepped.position == pytest.approx(pose.position + drift.offset)
    assert stepped.yaw == pytest.approx(0.5 + drift.yaw_offset)


def test_the_noisy_depth_is_numpys_array_form_to_the_bit() -> None:
    """The compiled pass gives what the array-by-array NumPy form gives, bit for bit:
    including NaN, depths near zero that the noise would push below it, and both strides."""
    cfg = DepthNoiseConfig(sigma_a=0.01, sigma_b=0.02)
    for shape in [(120, 160), (60, 80)]:
        depth = np.random.default_rng(1).uniform(0.0, 8.0, shape).astype(np.float32)
        depth[np.random.default_rng(2).random(shape) < 0.2] = np.nan
        depth[0, :20] = np.float32(1e-4)
        noise = np.random.default_rng(3).standard_normal(shape)
        reference = depth + (noise * depth_sigma(depth, cfg)).astype(np.float32)
        np.maximum(reference, np.float32(0.0), where=np.isfinite(reference), out=reference)
        got = add_depth_noise(depth, cfg, np.random.default_rng(3))
        assert got.dtype == np.float32 and got.shape == shape
        np.testing.assert_array_equal(got.view(np.uint32), reference.view(np.uint32))
        assert np.count_nonzero(got == 0.0) > 0
