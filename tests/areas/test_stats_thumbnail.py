"""Measured statistics on a hand-checkable building, PNG thumbnails, and the cache file."""

from __future__ import annotations

import zlib
from pathlib import Path

import numpy as np
import pytest

from areas import ground_truth
from areas.area import Area, AreaInfo
from areas.assemble import finish_area
from areas.ground_truth import compute_ground_truth, ground_truth_path, load_ground_truth
from areas.primitives import Parts, slab, wall
from areas.stats import face_order, flyable_voxels, level_heights, measure
from areas.thumbnail import render_perspective, render_top, write_png, write_thumbnails


def _two_storeys(hole: bool) -> Area:
    """A closed 6 x 4 x 6 m box with a floor at 3 m; with a 2 x 1.6 m hole in it, or none."""
    p = Parts()
    p.add(slab((0, 0, 6, 4), 0.0, 0.15), slab((0, 0, 6, 4), 5.85, 6.0))
    p.add(slab((0, 0, 6, 4), 2.9, 3.1, [(3.5, 1.0, 5.5, 2.6)] if hole else []))
    for axis, at in ((0, 0.1), (0, 3.9), (1, 0.1), (1, 5.9)):
        p.add(wall(axis, 0.0, 6.0 if axis == 0 else 4.0, at, 0.2, 0.0, 6.0))
    return finish_area(
        name="two", mesh=p.build(), bounds_min=np.zeros(3), bounds_max=np.array([6, 4, 6.0]),
        start=(2.0, 2.0, 1.3), yaw=0.0, plateau_s=10.0, voxel_size=0.1,
        info=AreaInfo(title="TWO", rooms=2, levels=2, complexity="low", indoor=True),
        generator_version=1, seed=0,
    )


def test_levels_need_an_opening() -> None:
    open_ = _two_storeys(hole=True)
    truth = compute_ground_truth(open_, sample_spacing=0.1)
    stats = measure(open_, truth)
    assert stats.levels == 2
    assert stats.level_heights == pytest.approx((0.15, 3.1), abs=0.06)
    assert stats.bounding == (6.0, 4.0, 6.0)
    assert stats.faces == len(open_.triangles)
    # Free space: 5.6 x 3.6 on both storeys (2.75 m each) plus the hole; the footprint is the
    # inner plan plus the surface layer around it.
    assert stats.volume_m3 == pytest.approx(5.6 * 3.6 * 5.5 + 2 * 1.6 * 0.2, rel=0.05)
    assert stats.area_m2 == pytest.approx(5.6 * 3.6, rel=0.15)
    assert len(level_heights(open_, flyable_voxels(open_))) == 2

    closed = _two_storeys(hole=False)
    assert measure(closed, compute_ground_truth(closed, sample_spacing=0.1)).levels == 1
    assert len(level_heights(closed, flyable_voxels(closed))) == 1


def test_a_gap_too_small_for_the_vehicle_is_not_flyable() -> None:
    area = _two_storeys(hole=True)
    # The same building with a 0.5 m hole: the flood fill passes, the vehicle does not.
    p = Parts()
    p.add(slab((0, 0, 6, 4), 0.0, 0.15), slab((0, 0, 6, 4), 5.85, 6.0))
    p.add(slab((0, 0, 6, 4), 2.9, 3.1, [(4.0, 1.5, 4.5, 2.0)]))
    for axis, at in ((0, 0.1), (0, 3.9), (1, 0.1), (1, 5.9)):
        p.add(wall(axis, 0.0, 6.0 if axis == 0 else 4.0, at, 0.2, 0.0, 6.0))
    narrow = finish_area(
        name="narrow", mesh=p.build(), bounds_min=area.bounds_min, bounds_max=area.bounds_max,
        start=(2.0, 2.0, 1.3), yaw=0.0, plateau_s=10.0, voxel_size=0.1, info=area.info,
        generator_version=1, seed=0,
    )
    # The upper storey is free space the vehicle can neither reach nor see (a level camera
    # looks through the hole at no more than 36.85 degrees): one level, and the ground truth
    # says how much lies out of reach.
    truth = compute_ground_truth(narrow, sample_spacing=0.1)
    assert measure(narrow, truth).levels == 1
    assert len(level_heights(narrow, flyable_voxels(narrow))) == 1
    # The storeys are alike: about half the free space is the upper one.
    assert truth.unobservable_free_m3 == pytest.approx(0.5 * truth.free_volume_m3, rel=0.1)


def test_face_order() -> None:
    assert face_order(130) == 2
    assert face_order(6910) == 4
    assert face_order(316_000) == 5
    assert face_order(857_000) == 6


def test_png_is_valid(tmp_path: Path) -> None:
    image = np.zeros((3, 4, 3), dtype=np.uint8)
    image[1, 2] = (255, 128, 0)
    path = tmp_path / "x.png"
    write_png(path, image)
    data = path.read_bytes()
    assert data.startswith(b"\x89PNG\r\n\x1a\n")
    assert int.from_bytes(data[16:20], "big") == 4  # width
    assert int.from_bytes(data[20:24], "big") == 3  # height
    idat = data.index(b"IDAT")
    length = int.from_bytes(data[idat - 4 : idat], "big")
    raw = zlib.decompress(data[idat + 4 : idat + 4 + length])
    rows = np.frombuffer(raw, dtype=np.uint8).reshape(3, 1 + 4 * 3)
    assert rows[:, 0].tolist() == [0, 0, 0]
    assert rows[1, 1 + 2 * 3 : 1 + 3 * 3].tolist() == [255, 128, 0]


def test_thumbnails_show_the_area(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("FLYBO_CACHE_DIR", str(tmp_path))
    area = _two_storeys(hole=True)
    top = render_top(area, max_side=60)
    assert top.shape == (40, 60, 3)
    persp = render_perspective(area, 64, 48)
    assert persp.shape == (48, 64, 3)
    # The roof is left out, so the top view sees the upper floor and, through the hole (at
    # x 3.5-5.5, y 1-2.6 m; 10 pixels a metre, y up), the lower one, darker as it is lower.
    floor, through_hole = top[30, 15].astype(int), top[22, 45].astype(int)
    assert floor.sum() > through_hole.sum()
    paths = write_thumbnails(area)
    assert [p.name for p in paths] == ["two-g1-s0-top.png", "two-g1-s0-perspective.png"]
    assert all(p.parent == tmp_path / "thumbnails" and p.stat().st_size > 100 for p in paths)


def test_cache_file_is_named_by_generator_version_and_seed(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("FLYBO_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(ground_truth, "_memory_cache", {})
    area = _two_storeys(hole=True)
    first = load_ground_truth(area)
    path = ground_truth_path(area)
    assert path == tmp_path / "ground_truth" / "two-g1-s0.npz"
    monkeypatch.setattr(ground_truth, "_memory_cache", {})
    again = load_ground_truth(area)
    np.testing.assert_array_equal(again.observable, first.observable)
    # Stored as uint16 steps: within half a millimetre of the computed points.
    assert np.abs(again.surface_points - first.surface_points).max() <= 5e-4
    # Same key, other geometry (a generator changed without a version bump): recomputed.
    other = _two_storeys(hole=False)
    assert other.cache_key == area.cache_key
    assert ground_truth._read(path, other) is None
    monkeypatch.setattr(ground_truth, "_memory_cache", {})
    assert load_ground_truth(other).observable_volume_m3 < first.observable_volume_m3
