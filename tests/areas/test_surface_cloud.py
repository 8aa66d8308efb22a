"""The ground truth's surface cloud: packed storage, decoding in slices, the fixed subsample."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pytest

from areas import surface_cloud
from areas.surface_cloud import QUANTUM, TRUTH_SAMPLE_SEED, SurfaceCloud


def _points(n: int, hi: tuple[float, float, float] = (40.0, 30.0, 12.0)) -> npt.NDArray[np.float32]:
    rng = np.random.default_rng(3)
    return rng.uniform([-5.0, 2.0, 0.0], hi, size=(n, 3)).astype(np.float32)


def test_packed_cloud_decodes_in_slices_to_the_whole_decode(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # Slices of 1,000 rows over 2,500 points: whole slices and a partial last one.
    monkeypatch.setattr(surface_cloud, "DECODE_ROWS", 1000)
    points = _points(2500)
    packed = SurfaceCloud.of(points).packed()
    assert packed.codes is not None and packed.plain is None
    assert packed.origin is not None and packed.step is not None
    whole = (packed.codes.astype(np.float64) * packed.step + packed.origin).astype(np.float32)
    decoded = packed.points()
    assert decoded.dtype == np.float32
    assert np.array_equal(decoded, whole)
    assert float(np.abs(decoded - points).max()) <= QUANTUM / 2 + 1e-6
    # The codes, as stored, are the same whatever the slice size.
    monkeypatch.setattr(surface_cloud, "DECODE_ROWS", 1 << 20)
    assert np.array_equal(SurfaceCloud.of(points).packed().codes, packed.codes)


def test_packed_cloud_holds_half_the_bytes_and_round_trips_its_arrays() -> None:
    points = _points(10_000)
    packed = SurfaceCloud.of(points).packed()
    assert packed.nbytes == points.nbytes // 2
    again = SurfaceCloud.from_arrays(packed.arrays())
    assert np.array_equal(again.points(), packed.points())
    assert len(again) == len(points)


def test_a_cloud_too_wide_for_uint16_steps_stays_float32() -> None:
    wide = _points(100, hi=(100.0, 30.0, 12.0))  # 105 m: steps would exceed QUANTUM
    packed = SurfaceCloud.of(wide).packed()
    assert packed.codes is None
    assert np.array_equal(SurfaceCloud.from_arrays(packed.arrays()).points(), wide)


@pytest.mark.parametrize("pack", [False, True])
def test_the_sample_is_the_seeded_choice_of_the_decoded_cloud(pack: bool) -> None:
    cloud = SurfaceCloud.of(_points(50_000))
    if pack:
        cloud = cloud.packed()
    full = cloud.points()
    rows = np.sort(np.random.default_rng(TRUTH_SAMPLE_SEED).choice(len(full), 1234, replace=False))
    sample = cloud.sample(1234)
    assert sample.dtype == np.float32 and sample.shape == (1234, 3)
    assert np.array_equal(sample, full[rows])
    assert np.array_equal(cloud.sample(1234), sample)
    # A sample at least the cloud's size is the whole cloud.
    assert np.array_equal(cloud.sample(len(full)), full)


def test_an_empty_cloud_samples_and_decodes_to_no_points() -> None:
    empty = SurfaceCloud.of(np.zeros((0, 3), np.float32)).packed()
    assert len(empty) == 0
    assert empty.points().shape == (0, 3)
    assert empty.sample(10).shape == (0, 3)
