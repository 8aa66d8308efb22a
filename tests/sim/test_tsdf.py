"""TSDF fusion: signed distance read-back and the recall it gives."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from benchmarks.bookkeeping_ops import read_through_table
from sim.camera import DepthCamera
from sim.geometry import Pose
from sim.metrics import sdf_surface_recall, surface_recall
from sim.tsdf import TsdfConfig, TsdfVolume


def _box(size: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    """Closed box [0, size] as (8, 3) vertices and (12, 3) triangles."""
    sx, sy, sz = size
    v = np.array([[x, y, z] for x in (0, sx) for y in (0, sy) for z in (0, sz)], dtype=float)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tris = [t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))]
    return v, np.array(tris, dtype=np.int32)


@pytest.fixture(scope="module")
def fused() -> tuple[TsdfVolume, np.ndarray]:
    vertices, triangles = _box((4.0, 3.0, 2.5))
    camera = DepthCamera(vertices, triangles)
    volume = TsdfVolume(camera.config.intrinsic_matrix(), 5.0, TsdfConfig())
    for yaw in np.arange(0.0, 2 * np.pi, 0.3):
        pose = Pose(np.array([2.0, 1.5, 1.25]), float(yaw))
        volume.integrate(camera.render(pose).depth, pose)
    # Points on the x = 4 wall, away from edges the level camera cannot see.
    rng = np.random.default_rng(0)
    wall = np.column_stack([np.full(500, 4.0), rng.uniform(0.5, 2.5, 500),
                            rng.uniform(0.8, 1.7, 500)])
    return volume, wall


def test_sdf_is_zero_on_the_surface_and_signed_off_it(fused: tuple[TsdfVolume, np.ndarray]) -> None:
    volume, wall = fused
    sdf, weight = volume.sdf_at(wall)
    assert np.all(weight >= 1.0)
    assert np.max(np.abs(sdf)) < 0.02
    inside, _ = volume.sdf_at(wall - [0.05, 0.0, 0.0])  # 5 cm in front of the wall, seen side
    assert np.all(inside > 0.02)
    assert np.median(inside) == pytest.approx(0.05, abs=0.01)


def test_unobserved_points_have_no_weight(fused: tuple[TsdfVolume, np.ndarray]) -> None:
    volume, _ = fused
    sdf, weight = volume.sdf_at(np.array([[50.0, 50.0, 50.0]]))
    assert np.isnan(sdf[0]) and weight[0] == 0.0


def test_sdf_recall_agrees_with_point_recall(fused: tuple[TsdfVolume, np.ndarray]) -> None:
    volume, wall = fused
    sdf, weight = volume.sdf_at(wall)
    by_sdf = sdf_surface_recall(sdf, weight, 0.05, volume.config.weight_threshold)
    by_points = surface_recall(volume.surface_points(), wall, 0.05)
    assert by_sdf == pytest.approx(by_points, abs=0.01)
    assert by_sdf > 0.99
    # Far from any surface: not recalled.
    off, off_w = volume.sdf_at(wall - [1.0, 0.0, 0.0])
    assert sdf_surface_recall(off, off_w, 0.05, 1.0) == 0.0


def _box_flight(config: TsdfConfig, expected_blocks: int = 0) -> TsdfVolume:
    vertices, triangles = _box((6.0, 5.0, 2.5))
    camera = DepthCamera(vertices, triangles)
    volume = TsdfVolume(camera.config.intrinsic_matrix(), 5.0, config, expected_blocks)
    for k, yaw in enumerate(np.arange(0.0, 2 * np.pi, 0.25)):
        pose = Pose(np.array([1.5 + 0.1 * k, 2.5, 1.25]), float(yaw))
        volume.integrate(camera.render(pose).depth, pose)
    return volume


def test_a_block_table_grown_many_times_holds_the_same_field() -> None:
    """The table grows by BLOCK_GROWTH before Open3D would double it; a run reads the TSDF by
    block key, so a table that grew from 100 blocks gives the same field, points and mesh as
    one that never had to grow."""
    from sim.tsdf import BLOCK_GROWTH

    grown = _box_flight(TsdfConfig(initial_block_count=100))
    whole = _box_flight(TsdfConfig(initial_block_count=20_000))
    used = grown._grid.hashmap().size()
    assert used == whole._grid.hashmap().size() > 1_000
    # It grew from 100 blocks by the factor, not by doubling (which would have left it at
    # 1,600 blocks for these 1,264).
    assert used <= grown._grid.hashmap().capacity() <= np.ceil(used * BLOCK_GROWTH)

    rng = np.random.default_rng(3)
    probes = rng.uniform([-0.2, -0.2, -0.2], [6.2, 5.2, 2.7], size=(20_000, 3))
    for a, b in zip(grown.sdf_at(probes), whole.sdf_at(probes), strict=True):
        np.testing.assert_array_equal(a, b)

    def rows(points: np.ndarray) -> np.ndarray:
        return points[np.lexsort(points.T[::-1])]

    np.testing.assert_array_equal(rows(grown.surface_points()), rows(whole.surface_points()))
    (gv, gt), (wv, wt) = grown.mesh(), whole.mesh()
    np.testing.assert_array_equal(rows(gv), rows(wv))
    assert len(gt) == len(wt)
    np.testing.assert_array_equal(rows(np.sort(gv[gt].reshape(len(gt), 9), axis=1)),
                                  rows(np.sort(wv[wt].reshape(len(wt), 9), axis=1)))


def test_surface_points_are_open3ds_extraction_in_block_key_order() -> None:
    """`surface_points` gives the points of Open3D's own extraction, bit for bit (its threads
    order them differently from one call to the next; ours go by block key, the same every
    time), crossings between blocks included."""
    volume = _box_flight(TsdfConfig())

    def rows(points: np.ndarray) -> np.ndarray:
        return points[np.lexsort(points.T[::-1])]

    counted = volume._grid.extract_point_cloud(volume.config.weight_threshold)
    expected = rows(counted.point.positions.numpy())
    points = volume.surface_points()
    assert points.dtype == np.float32 and len(points) > 1000
    np.testing.assert_array_equal(rows(points), expected)
    np.testing.assert_array_equal(volume.surface_points(), points)
    # Crossings between two blocks: past the last voxel sample of a block along an axis.
    res = volume.config.block_resolution
    voxels = points.astype(np.float64) / volume.config.voxel_size_m
    within_block = voxels - np.floor(voxels / res) * res
    assert np.count_nonzero(within_block > res - 1 + 1e-3) > 100


def test_surface_points_of_an_empty_grid_and_a_high_threshold() -> None:
    volume = TsdfVolume(np.eye(3), 5.0, TsdfConfig())
    assert volume.surface_points().shape == (0, 3)
    flown = _box_flight(TsdfConfig(weight_threshold=1e9))
    assert flown.surface_points().shape == (0, 3)


def _box_surface(size: tuple[float, float, float], step: float) -> np.ndarray:
    """(N, 3) points on the six faces of the box [0, size], `step` apart."""
    axes = [np.arange(0.0, s + 1e-9, step) for s in size]
    faces = []
    for a in range(3):
        b, c = [x for x in range(3) if x != a]
        gb, gc = np.meshgrid(axes[b], axes[c], indexing="ij")
        for value in (0.0, size[a]):
            face = np.zeros((gb.size, 3))
            face[:, a], face[:, b], face[:, c] = value, gb.ravel(), gc.ravel()
            faces.append(face)
    return np.concatenate(faces)


def test_surface_block_count_sizes_the_table_for_a_flight_of_that_surface() -> None:
    """The blocks within the truncation of a box's surface are about the blocks a flight
    inside it fuses (at most a fifth more); the table starts with room for them."""
    from sim.tsdf import EXPECTED_BLOCK_MARGIN, surface_block_count

    config = TsdfConfig(initial_block_count=100)
    expected = surface_block_count(_box_surface((6.0, 5.0, 2.5), 0.05), config)
    flown = _box_flight(config)._grid.hashmap().size()
    assert flown <= expected <= 1.2 * flown, (flown, expected)

    made = TsdfVolume(np.eye(3), 5.0, config, expected_blocks=expected)
    assert made._grid.hashmap().capacity() == np.ceil(expected * EXPECTED_BLOCK_MARGIN)
    sized = _box_flight(config, expected_blocks=expected)
    assert sized._grid.hashmap().size() == flown
    # Corner cases: a point at a block's centre is in one block, on a face in two.
    block = config.voxel_size_m * config.block_resolution
    assert surface_block_count(np.array([[block / 2] * 3]), config) == 1
    assert surface_block_count(np.array([[0.0, block / 2, block / 2]]), config) == 2
    assert surface_block_count(np.zeros((0, 3)), config) == 0


def test_sdf_at_reads_the_field_as_open3ds_block_table_gives_it() -> None:
    """The compiled reading (`sim.tsdf_sampling`) gives, bit for bit, the trilinear field and
    least weight read through Open3D's block table, inside, outside and across blocks."""
    volume = _box_flight(TsdfConfig())
    rng = np.random.default_rng(11)
    probes = np.vstack([rng.uniform([-0.5, -0.5, -0.5], [6.5, 5.5, 3.0], size=(30_000, 3)),
                        rng.uniform(-0.1, 0.1, size=(2_000, 3)) + np.array([6.0, 2.5, 1.25])])
    sdf, weight = volume.sdf_at(probes)
    ref_sdf, ref_weight = read_through_table(volume, probes)
    np.testing.assert_array_equal(sdf, ref_sdf)
    np.testing.assert_array_equal(weight, ref_weight)
    assert weight.dtype == np.float32
    seen = np.isfinite(sdf)
    assert 1_000 < np.count_nonzero(seen) < len(probes)


def test_a_frame_is_cleaned_as_numpy_cleans_it() -> None:
    """The compiled pass gives `np.nan_to_num(depth, nan=0.0)` to the bit and says whether a
    depth lies within range as NumPy's float32 comparison does, at the range's edge too."""
    from sim.tsdf import _without_nan

    rng = np.random.default_rng(4)
    depth = rng.uniform(-1.0, 7.0, (60, 80)).astype(np.float32)
    depth[rng.random(depth.shape) < 0.2] = np.nan
    depth[0, :3] = [np.inf, -np.inf, 0.0]
    depth[1, 0] = np.float32(4.5)
    for max_range in (4.5, 0.1, 5.0000001):
        clean, within = _without_nan(depth.reshape(-1), np.float32(max_range))
        expected = np.nan_to_num(depth, nan=0.0).astype(np.float32)
        np.testing.assert_array_equal(clean.reshape(depth.shape).view(np.uint32),
                                      expected.view(np.uint32))
        assert within == bool(np.any((expected > 0.0) & (expected <= max_range)))
    edge = np.array([np.nan, np.float32(0.1), -2.0], dtype=np.float32)
    assert _without_nan(edge, np.float32(0.1))[1] == bool(np.any((edge > 0) & (edge <= 0.1)))
    assert not _without_nan(np.full(4, np.nan, dtype=np.float32), np.float32(5.0))[1]
