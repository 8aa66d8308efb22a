"""The compiled fusion of a depth frame: Open3D's `VoxelBlockGrid.integrate` values, to the bit,
over the blocks Open3D's `compute_unique_block_coordinates` gives, the same set."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pytest

from areas import load_area
from sim.camera import CameraConfig, DepthCamera
from sim.geometry import Pose
from sim.open3d_any import o3c
from sim.tsdf import TsdfConfig, TsdfVolume
from sim.tsdf_blocks import block_arrays, block_grid
from sim.tsdf_fusion import (
    FusionParameters,
    fuse_depth,
    open3d_blocks,
    open3d_fuse,
    touched_blocks,
)

View = tuple[npt.NDArray[np.float32], Pose]


def _contents(grid: object) -> tuple[npt.NDArray[np.int32], npt.NDArray[np.uint32],
                                     npt.NDArray[np.float32]]:
    """The allocated blocks' keys, tsdf bits and weights, in key order (slots aside)."""
    blocks = block_arrays(grid)
    assert blocks is not None
    return (blocks.keys[blocks.order], blocks.tsdf[blocks.order].view(np.uint32),
            blocks.weight[blocks.order])


def _assert_same_grids(a: object, b: object) -> int:
    keys_a, tsdf_a, weight_a = _contents(a)
    keys_b, tsdf_b, weight_b = _contents(b)
    assert np.array_equal(keys_a, keys_b)
    assert np.array_equal(weight_a, weight_b)
    assert np.array_equal(tsdf_a, tsdf_b)
    return int((weight_a > 0).sum())


def _assert_same_blocks(grid: object, depth: npt.NDArray[np.float32],
                        intrinsic: npt.NDArray[np.float64], extrinsic: npt.NDArray[np.float64],
                        config: TsdfConfig, depth_max: float) -> npt.NDArray[np.int32]:
    """`touched_blocks` against Open3D's on one frame: the same set (Open3D's keys returned)."""
    theirs = open3d_blocks(grid, depth, intrinsic, extrinsic, config.trunc_voxel_multiplier,
                           depth_max)
    params = FusionParameters.of(intrinsic, config.voxel_size_m, config.trunc_voxel_multiplier,
                                 depth_max)
    ours = touched_blocks(depth, extrinsic, params, config.block_resolution)
    assert ours.dtype == np.int32 and ours.shape[1:] == (3,)
    np.testing.assert_array_equal(np.unique(ours, axis=0), np.unique(theirs, axis=0))
    assert len(ours) == len(theirs)  # each block once
    return theirs


def _views(area_name: str, count: int, seed: int, camera_config: CameraConfig | None = None,
           noise_m: float = 0.02) -> tuple[DepthCamera, list[View]]:
    """`count` noisy views from random poses around the area's start (NaN where no return)."""
    area = load_area(area_name)
    camera = DepthCamera(area.vertices, area.triangles, camera_config or CameraConfig())
    rng = np.random.default_rng(seed)
    start = np.asarray(area.start.position, dtype=np.float64)
    views = []
    for _ in range(count):
        pose = Pose(start + rng.uniform([-1.5, -1.5, -0.3], [1.5, 1.5, 0.6]),
                    float(rng.uniform(-np.pi, np.pi)))
        depth = camera.render(pose).depth
        noisy = depth + rng.normal(0.0, noise_m, depth.shape).astype(np.float32)
        views.append((noisy.astype(np.float32), pose))
    return camera, views


def _fuse_both(views: list[View], intrinsic: npt.NDArray[np.float64], config: TsdfConfig,
               depth_max: float, extra_blocks: int = 0, capacity: int = 20000) -> int:
    """Fuse the views into two grids, Open3D's way and the compiled way, over Open3D's touched
    blocks (plus, with `extra_blocks`, a cube of blocks of that half-width around the camera,
    most of them behind it or outside the image); compare the grids after every frame, and
    the touched blocks with `touched_blocks`'."""
    ours = block_grid(config.voxel_size_m, config.block_resolution, capacity)
    theirs = block_grid(config.voxel_size_m, config.block_resolution, capacity)
    params = FusionParameters.of(intrinsic, config.voxel_size_m, config.trunc_voxel_multiplier,
                                 depth_max)
    block = config.voxel_size_m * config.block_resolution
    fused = 0
    for depth, pose in views:
        clean = np.nan_to_num(depth, nan=0.0).astype(np.float32)
        extrinsic = TsdfVolume.extrinsic(pose)
        # Empty when no return is within range (a pose facing a wall's back).
        coords = _assert_same_blocks(theirs, clean, intrinsic, extrinsic, config, depth_max)
        if extra_blocks:
            centre = np.floor(pose.position / block).astype(np.int32)
            span = np.arange(-extra_blocks, extra_blocks + 1, dtype=np.int32)
            cube = np.stack(np.meshgrid(span, span, span, indexing="ij"), -1).reshape(-1, 3)
            coords = np.unique(np.concatenate([coords, centre + cube]), axis=0)
        if len(coords) == 0:
            continue
        tensor = o3c.Tensor(np.ascontiguousarray(coords, dtype=np.int32))
        open3d_fuse(theirs, tensor, clean, intrinsic, extrinsic, config.trunc_voxel_multiplier,
                    depth_max)
        fuse_depth(ours, tensor, clean, extrinsic, params)
        fused = _assert_same_grids(ours, theirs)
    return fused


def test_noisy_views_of_maze_fuse_as_open3d_fuses_them() -> None:
    camera, views = _views("maze", 24, seed=0)
    assert _fuse_both(views, camera.config.intrinsic_matrix(), TsdfConfig(), 5.0) > 50_000


def test_a_full_block_table_grows_while_fusing() -> None:
    """Blocks beyond the table's capacity: the table grows inside `fuse_depth`'s activation, and
    the fusion writes into the grown table's arrays."""
    camera, views = _views("maze", 6, seed=6)
    # Over 60,000 fused voxels fill more than 100 blocks of 512.
    assert _fuse_both(views, camera.config.intrinsic_matrix(), TsdfConfig(), 5.0,
                      capacity=100) > 60_000


def test_voxels_behind_the_camera_and_outside_the_image_are_left_alone() -> None:
    camera, views = _views("maze", 6, seed=1)
    config = TsdfConfig(voxel_size_m=0.1)
    assert _fuse_both(views, camera.config.intrinsic_matrix(), config, 5.0, extra_blocks=3) > 0


@pytest.mark.parametrize(("voxel", "res", "mult", "depth_max"), [
    (0.05, 4, 3.0, 5.0), (0.05, 13, 1.7, 3.0), (0.08, 8, 4.5, 8.0), (0.037, 6, 2.3, 2.5),
])
def test_grid_and_camera_settings_fuse_as_open3d_fuses_them(
        voxel: float, res: int, mult: float, depth_max: float) -> None:
    camera, views = _views("offices-a", 8, seed=2,
                           camera_config=CameraConfig(width=96, height=72, fov_h_deg=70.0))
    config = TsdfConfig(voxel_size_m=voxel, block_resolution=res, trunc_voxel_multiplier=mult)
    assert _fuse_both(views, camera.config.intrinsic_matrix(), config, depth_max) > 1000


def test_returns_at_and_beyond_the_range_and_missing_ones() -> None:
    """Depths of exactly 0, exactly the maximum, just above it and far beyond it."""
    camera, views = _views("maze", 4, seed=3, noise_m=0.0)
    rng = np.random.default_rng(4)
    edited = []
    for depth, pose in views:
        d = depth.copy()
        pick = rng.random(d.shape)
        d[pick < 0.1] = np.nan
        d[(pick >= 0.1) & (pick < 0.2)] = np.float32(3.0)
        d[(pick >= 0.2) & (pick < 0.3)] = np.nextafter(np.float32(3.0), np.float32(4.0))
        d[(pick >= 0.3) & (pick < 0.35)] = np.float32(40.0)
        edited.append((d, pose))
    assert _fuse_both(edited, camera.config.intrinsic_matrix(), TsdfConfig(), 3.0) > 1000


def test_the_volume_fuses_as_open3d_fuses() -> None:
    """`TsdfVolume.integrate` (NaN cleaning, the compiled block coordinates, the table's growth,
    the compiled fusion) against Open3D's two calls on the same frames."""
    camera, views = _views("maze", 10, seed=5)
    config = TsdfConfig(initial_block_count=100)  # grows the table mid-way
    volume = TsdfVolume(camera.config.intrinsic_matrix(), 5.0, config)
    reference = block_grid(config.voxel_size_m, config.block_resolution, 100)
    k = camera.config.intrinsic_matrix()
    for depth, pose in views:
        volume.integrate(depth, pose)
        clean = np.nan_to_num(depth, nan=0.0)
        extrinsic = TsdfVolume.extrinsic(pose)
        coords = open3d_blocks(reference, clean, k, extrinsic, 3.0, 5.0)
        if len(coords) == 0:  # no return within range: the volume fuses nothing either
            continue
        open3d_fuse(reference, o3c.Tensor(coords), clean, k, extrinsic, 3.0, 5.0)
    assert volume.grid.hashmap().capacity() > 100
    assert _assert_same_grids(volume.grid, reference) > 10_000


@pytest.mark.parametrize("depth_value", [1.25, 1.5, 2.0, 2.75, 3.0, 3.5])
def test_exact_boundaries_fuse_as_open3d_fuses_them(depth_value: float) -> None:
    """Binary-exact numbers so that voxels land exactly on the boundaries: on the image's last
    column and row (u = W - 1, v = H - 1), at zc = 0, at a depth exactly at the maximum (3.0)
    and with the signed distance exactly minus and plus the truncation (0.75 with the voxels
    at z = 2.0: depths 1.25 and 2.75)."""
    voxel, res, mult, depth_max = 0.25, 4, 3.0, 3.0
    width, height = 16, 12
    # u = 10 * x / z + 10: the voxel at x = 1, z = 2 projects to u = 15 = W - 1 exactly.
    intrinsic = np.array([[10.0, 0.0, 10.0], [0.0, 10.0, 6.0], [0.0, 0.0, 1.0]])
    extrinsic = np.eye(4)  # the optical frame is the world's
    depth = np.full((height, width), depth_value, dtype=np.float32)
    span = np.arange(-3, 3, dtype=np.int32)
    keys = np.stack(np.meshgrid(span, span, np.arange(0, 4, dtype=np.int32), indexing="ij"),
                    -1).reshape(-1, 3)
    ours = block_grid(voxel, res, 1000)
    theirs = block_grid(voxel, res, 1000)
    tensor = o3c.Tensor(np.ascontiguousarray(keys))
    for _ in range(2):
        open3d_fuse(theirs, tensor, depth, intrinsic, extrinsic, mult, depth_max)
        fuse_depth(ours, tensor, depth, extrinsic,
                   FusionParameters.of(intrinsic, voxel, mult, depth_max))
    fused = _assert_same_grids(ours, theirs)
    assert (fused > 0) == (depth_value <= depth_max)


@pytest.mark.parametrize(("width", "height"), [(98, 75), (161, 123), (4, 4), (3, 9)])
def test_image_sizes_touch_the_blocks_open3d_touches(width: int, height: int) -> None:
    """Images whose sides are not multiples of Open3D's stride of 4 (its last, partial row and
    column of samples are dropped), and one smaller than a stride: the same blocks."""
    camera, views = _views("offices-a", 6, seed=8,
                           camera_config=CameraConfig(width=width, height=height))
    config = TsdfConfig()
    grid = block_grid(config.voxel_size_m, config.block_resolution, 1000)
    for depth, pose in views:
        _assert_same_blocks(grid, np.nan_to_num(depth, nan=0.0), camera.config.intrinsic_matrix(),
                            TsdfVolume.extrinsic(pose), config, 5.0)


@pytest.mark.parametrize("depth_value", [0.0, 0.5, 1.0, 1.75, 2.25, 3.0, 3.25])
def test_exact_block_boundaries_touch_the_blocks_open3d_touches(depth_value: float) -> None:
    """Binary-exact numbers so that the samples along each ray land exactly on block faces
    (blocks of 0.25 m, truncation 0.25 m, samples every sixth of a metre from depth - 0.25):
    depths of exactly 0 and exactly the maximum (3.0, left out: the comparison is open there),
    a camera moved by whole and half blocks, turned a quarter."""
    voxel, res, mult, depth_max = 0.0625, 4, 4.0, 3.0
    width, height = 16, 12
    intrinsic = np.array([[8.0, 0.0, 8.0], [0.0, 8.0, 6.0], [0.0, 0.0, 1.0]])
    config = TsdfConfig(voxel_size_m=voxel, block_resolution=res, trunc_voxel_multiplier=mult)
    grid = block_grid(voxel, res, 1000)
    depth = np.full((height, width), depth_value, dtype=np.float32)
    for shift, quarter in (((0.0, 0.0, 0.0), False), ((0.5, -0.25, 0.125), False),
                           ((-1.0, 0.75, 0.25), True)):
        extrinsic = np.eye(4)
        if quarter:
            extrinsic[:3, :3] = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
        extrinsic[:3, 3] = shift
        touched = _assert_same_blocks(grid, depth, intrinsic, extrinsic, config, depth_max)
        assert (len(touched) > 0) == (0.0 < depth_value < depth_max)
