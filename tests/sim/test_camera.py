"""Depth camera: ray-cast z-depth images of a closed box against analytic plane intersections."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import open3d as o3d
import pytest
from pydantic import ValidationError

from sim.camera import BODY_FROM_OPTICAL, CameraConfig, DepthCamera
from sim.geometry import Pose, yaw_matrix

FloatArray = npt.NDArray[np.float64]

BOX_MIN = np.zeros(3)
BOX_MAX = np.array([4.0, 4.0, 3.0])
# Inside the box: 1.0 from x=0, 3.0 from x=4, 1.5 from y=0, 2.5 from y=4, 1.2 from z=0,
# 1.8 from z=3.
POSITION = np.array([1.0, 1.5, 1.2])
# Odd size: pixel (60, 80) has its centre exactly on the principal point (the optical axis).
ODD = CameraConfig(width=161, height=121)
CENTRE = (60, 80)


def box_mesh() -> tuple[FloatArray, npt.NDArray[np.int32]]:
    mesh = o3d.geometry.TriangleMesh.create_box(*BOX_MAX)
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    triangles = np.asarray(mesh.triangles, dtype=np.int32)
    assert vertices.min(axis=0) == pytest.approx(BOX_MIN)
    assert vertices.max(axis=0) == pytest.approx(BOX_MAX)
    return vertices, triangles


def camera(config: CameraConfig | None = None) -> DepthCamera:
    vertices, triangles = box_mesh()
    return DepthCamera(vertices, triangles, config)


def optical_directions(config: CameraConfig) -> FloatArray:
    """(H, W, 3) optical-frame pixel directions with z = 1, computed from K independently."""
    k = config.intrinsic_matrix()
    u, v = np.meshgrid(np.arange(config.width) + 0.5, np.arange(config.height) + 0.5)
    return np.stack([(u - k[0, 2]) / k[0, 0], (v - k[1, 2]) / k[1, 1], np.ones_like(u)], axis=-1)


def world_from_optical(yaw: float) -> FloatArray:
    # Optical z (forward) = body x, optical x (right) = body -y, optical y (down) = body -z.
    body = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    return yaw_matrix(yaw) @ body


def analytic_depth(config: CameraConfig, position: FloatArray, yaw: float) -> FloatArray:
    """(H, W) z-depth of the first box face hit from inside: the scale of the z = 1 direction."""
    dirs = optical_directions(config) @ world_from_optical(yaw).T
    with np.errstate(divide="ignore", invalid="ignore"):
        to_max = np.where(dirs > 1e-12, (BOX_MAX - position) / dirs, np.inf)
        to_min = np.where(dirs < -1e-12, (BOX_MIN - position) / dirs, np.inf)
    return np.minimum(to_max, to_min).min(axis=-1)


def distance_to_box_faces(points: FloatArray) -> FloatArray:
    """(N,) distance of points inside the box to its nearest face."""
    return np.minimum(points - BOX_MIN, BOX_MAX - points).min(axis=1)


def test_body_from_optical_is_the_documented_rotation() -> None:
    assert np.allclose(BODY_FROM_OPTICAL @ BODY_FROM_OPTICAL.T, np.eye(3))
    assert np.linalg.det(BODY_FROM_OPTICAL) == pytest.approx(1.0)
    assert np.array_equal(BODY_FROM_OPTICAL @ [0, 0, 1], [1.0, 0.0, 0.0])  # forward
    assert np.array_equal(BODY_FROM_OPTICAL @ [1, 0, 0], [0.0, -1.0, 0.0])  # right
    assert np.array_equal(BODY_FROM_OPTICAL @ [0, 1, 0], [0.0, 0.0, -1.0])  # down


def test_intrinsics_match_the_field_of_view() -> None:
    cfg = CameraConfig()
    k = cfg.intrinsic_matrix()
    assert k[0, 0] == pytest.approx(80.0)  # 90 degrees over 160 pixels
    assert (cfg.width / 2) / k[0, 0] == pytest.approx(np.tan(np.radians(cfg.fov_h_deg) / 2))
    assert (cfg.height / 2) / k[1, 1] == pytest.approx(np.tan(np.radians(cfg.fov_v_deg) / 2))
    assert k[0, 2] == 80.0 and k[1, 2] == 60.0
    assert np.array_equal(k[2], [0.0, 0.0, 1.0])
    assert k[0, 1] == 0.0 and k[1, 0] == 0.0
    narrow = CameraConfig(fov_h_deg=60.0, fov_v_deg=40.0, width=300, height=200)
    kn = narrow.intrinsic_matrix()
    assert 150.0 / kn[0, 0] == pytest.approx(np.tan(np.radians(30.0)))
    assert 100.0 / kn[1, 1] == pytest.approx(np.tan(np.radians(20.0)))


def test_camera_config_rejects_bad_values() -> None:
    with pytest.raises(ValidationError):
        CameraConfig(fov_h_deg=180.0)
    with pytest.raises(ValidationError):
        CameraConfig(width=1)
    with pytest.raises(ValidationError):
        CameraConfig(max_range_m=0.0)


def test_centre_pixel_depth_is_the_distance_to_the_facing_wall() -> None:
    cam = camera(ODD)
    frame = cam.render(Pose(POSITION, 0.0), time=1.25)
    assert frame.time == 1.25
    assert frame.depth.shape == (121, 161)
    assert frame.depth.dtype == np.float32
    assert frame.depth[CENTRE] == pytest.approx(3.0, abs=1e-5)  # wall x = 4


def test_a_closed_camera_renders_no_more() -> None:
    cam = camera(ODD)
    cam.close()
    assert cam.closed
    with pytest.raises(RuntimeError, match="closed"):
        cam.render(Pose(POSITION, 0.0))
    with pytest.raises(RuntimeError, match="closed"):
        cam.distance_to_surface(POSITION)


@pytest.mark.parametrize(
    ("yaw", "distance"),
    [(0.0, 3.0), (np.pi / 2, 2.5), (np.pi, 1.0), (-np.pi / 2, 1.5)],
)
def test_yaw_rotates_the_view(yaw: float, distance: float) -> None:
    cam = camera(ODD)
    frame = cam.render(Pose(POSITION, yaw))
    assert frame.depth[CENTRE] == pytest.approx(distance, abs=1e-5)
    endpoints, hit = cam.back_project(frame.depth, Pose(POSITION, yaw))
    centre = endpoints[CENTRE[0] * ODD.width + CENTRE[1]]
    expected = POSITION + distance * np.array([np.cos(yaw), np.sin(yaw), 0.0])
    assert hit[CENTRE[0] * ODD.width + CENTRE[1]]
    assert centre == pytest.approx(expected, abs=1e-5)


@pytest.mark.parametrize("yaw", [0.0, np.pi / 2, np.pi, -np.pi / 2, 0.7, -2.4])
def test_whole_image_matches_analytic_z_depth(yaw: float) -> None:
    cfg = CameraConfig(max_range_m=10.0)
    cam = camera(cfg)
    depth = cam.render(Pose(POSITION, yaw)).depth
    expected = analytic_depth(cfg, POSITION, yaw)
    assert np.all(np.isfinite(depth))  # closed box, everything within 10 m
    assert np.allclose(depth, expected, rtol=0.0, atol=1e-4)


def test_z_depth_is_constant_on_a_wall_perpendicular_to_the_optical_axis() -> None:
    cfg = CameraConfig(max_range_m=10.0)
    cam = camera(cfg)
    position = np.array([1.0, 2.0, 1.5])  # centred on the wall x = 4, 3 m away
    depth = cam.render(Pose(position, 0.0)).depth
    # Pixels whose z-depth-3 point lies strictly inside the wall x = 4 see that wall.
    wall_points = position + 3.0 * optical_directions(cfg) @ world_from_optical(0.0).T
    margin = 0.02
    on_wall = (
        (wall_points[..., 1] > margin)
        & (wall_points[..., 1] < BOX_MAX[1] - margin)
        & (wall_points[..., 2] > margin)
        & (wall_points[..., 2] < BOX_MAX[2] - margin)
    )
    # The wall spans columns ~28..132 and rows ~21..98: not just the centre.
    assert on_wall.sum() > 0.4 * on_wall.size
    columns = np.flatnonzero(on_wall.any(axis=0))
    rows = np.flatnonzero(on_wall.any(axis=1))
    assert columns.min() < 30 and columns.max() > 130
    assert rows.min() < 25 and rows.max() > 95
    assert np.all(np.abs(depth[on_wall] - 3.0) < 1e-5)
    # Everything else (floor, ceiling, side walls) is nearer than the facing wall.
    assert np.all(depth[~on_wall] < 3.0 + 1e-5)
    # Nearest: the side walls 2 m away seen by the outermost columns, x = 79.5 / 80.
    assert depth[~on_wall].min() == pytest.approx(2.0 / (79.5 / 80.0), abs=1e-5)


def test_ray_length_is_z_depth_over_cosine_of_the_off_axis_angle() -> None:
    cfg = CameraConfig(max_range_m=10.0)
    cam = camera(cfg)
    pose = Pose(POSITION, 0.0)
    depth = cam.render(pose).depth
    endpoints, _ = cam.back_project(depth, pose)
    k = cfg.intrinsic_matrix()
    for row, col in [(10, 30), (60, 140), (100, 80), (0, 0), (119, 159)]:
        x = (col + 0.5 - k[0, 2]) / k[0, 0]
        y = (row + 0.5 - k[1, 2]) / k[1, 1]
        angle = np.arctan(np.hypot(x, y))
        z = float(depth[row, col])
        ray_length = np.linalg.norm(endpoints[row * cfg.width + col] - POSITION)
        assert ray_length == pytest.approx(z / np.cos(angle), rel=1e-6)
        assert ray_length > z  # off-axis pixels: the ray is longer than the z-depth
    # Pixel (30, 100) sees the facing wall: its ray length is 3 / cos(angle), by hand.
    row, col = 30, 100
    x = (col + 0.5 - 80.0) / 80.0
    y = (row + 0.5 - 60.0) / k[1, 1]
    assert np.linalg.norm(endpoints[row * cfg.width + col] - POSITION) == pytest.approx(
        3.0 * np.sqrt(1.0 + x * x + y * y), abs=1e-4
    )


def test_image_is_not_mirrored() -> None:
    cfg = CameraConfig(max_range_m=10.0)
    cam = camera(cfg)
    pose = Pose(POSITION, 0.0)
    endpoints, _ = cam.back_project(cam.render(pose).depth, pose)
    image = endpoints.reshape(cfg.height, cfg.width, 3)
    # Row 0 looks up, column 0 looks left (+y for yaw 0).
    assert image[0, 80, 2] > POSITION[2] > image[-1, 80, 2]
    assert image[60, 0, 1] > POSITION[1] > image[60, -1, 1]


def test_beyond_max_range_is_nan() -> None:
    cfg = CameraConfig(max_range_m=2.4)
    cam = camera(cfg)
    depth = cam.render(Pose(POSITION, 0.0)).depth
    expected = analytic_depth(cfg, POSITION, 0.0)
    clear = np.abs(expected - cfg.max_range_m) > 1e-3
    assert np.array_equal(np.isnan(depth)[clear], (expected > cfg.max_range_m)[clear])
    # The facing wall at 3 m is out of range; the floor below and the near walls are not.
    assert np.isnan(depth[60, 80])
    assert np.isnan(depth).sum() > 0.2 * depth.size
    assert np.isfinite(depth).sum() > 0.2 * depth.size
    assert np.nanmax(depth) <= cfg.max_range_m


def test_below_min_range_is_nan() -> None:
    cfg = CameraConfig(min_range_m=1.1, max_range_m=10.0)
    cam = camera(cfg)
    depth = cam.render(Pose(POSITION, np.pi)).depth  # wall x = 0 at 1.0 m
    assert np.isnan(depth[60, 80])
    expected = analytic_depth(cfg, POSITION, np.pi)
    clear = np.abs(expected - cfg.min_range_m) > 1e-3
    assert np.array_equal(np.isnan(depth)[clear], (expected < cfg.min_range_m)[clear])


def test_back_project_lands_on_the_mesh() -> None:
    cfg = CameraConfig(max_range_m=2.4)
    cam = camera(cfg)
    pose = Pose(np.array([2.2, 1.7, 1.4]), 0.9)
    frame = cam.render(pose)
    endpoints, hit = cam.back_project(frame.depth, pose)
    assert endpoints.shape == (cfg.height * cfg.width, 3)
    assert np.array_equal(hit, np.isfinite(frame.depth).reshape(-1))
    assert 0 < hit.sum() < hit.size
    on_surface = endpoints[hit]
    assert np.all(distance_to_box_faces(on_surface) < 1e-4)
    assert np.all((on_surface > BOX_MIN - 1e-4) & (on_surface < BOX_MAX + 1e-4))
    sample = on_surface[:: max(1, len(on_surface) // 200)]
    assert max(cam.distance_to_surface(p) for p in sample) < 1e-4
    # Pixels without a return end at the maximum range, measured along the optical axis.
    axis = yaw_matrix(pose.yaw) @ np.array([1.0, 0.0, 0.0])
    z_missed = (endpoints[~hit] - pose.position) @ axis
    assert np.allclose(z_missed, cfg.max_range_m)
    assert np.all(distance_to_box_faces(endpoints[~hit]) > -1e-9)  # still inside the box


def test_back_project_of_a_synthetic_depth_image() -> None:
    cfg = CameraConfig(width=4, height=2, fov_h_deg=90.0, fov_v_deg=90.0, max_range_m=5.0)
    cam = camera(cfg)
    depth = np.full((2, 4), 2.0, dtype=np.float32)
    depth[1, 3] = np.nan
    pose = Pose(np.array([1.0, 2.0, 1.5]), np.pi / 2)  # looking along +y
    endpoints, hit = cam.back_project(depth, pose)
    assert hit.tolist() == [True] * 7 + [False]
    # fx = 2, cx = 2: column 0 centre is at x = (0.5 - 2) / 2 = -0.75 (left, i.e. world -x).
    # fy = 1, cy = 1: row 0 centre is at y = -0.5 (up).
    assert endpoints[0] == pytest.approx([1.0 - 2.0 * 0.75, 2.0 + 2.0, 1.5 + 2.0 * 0.5])
    # Row 1, column 2: x = 0.25 (right, world +x), y = 0.5 (down).
    assert endpoints[6] == pytest.approx([1.0 + 2.0 * 0.25, 4.0, 1.5 - 2.0 * 0.5])
    # No return: the ray ends at z-depth 5 (the maximum range).
    assert endpoints[7] == pytest.approx([1.0 + 5.0 * 0.75, 2.0 + 5.0, 1.5 - 5.0 * 0.5])


def test_distance_to_surface() -> None:
    cam = camera()
    assert cam.distance_to_surface(POSITION) == pytest.approx(1.0, abs=1e-5)
    assert cam.distance_to_surface(np.array([2.0, 2.0, 0.25])) == pytest.approx(0.25, abs=1e-5)
    assert cam.distance_to_surface(np.array([2.0, 2.0, 1.5])) == pytest.approx(1.5, abs=1e-5)
    assert cam.distance_to_surface(np.array([5.0, 2.0, 1.5])) == pytest.approx(1.0, abs=1e-5)
    # Outside, off a corner: distance to the corner point (4, 4, 3).
    assert cam.distance_to_surface(np.array([5.0, 6.0, 5.0])) == pytest.approx(3.0, abs=1e-5)
    assert cam.distance_to_surface(np.array([4.0, 1.0, 1.0])) == pytest.approx(0.0, abs=1e-6)


class _NudgedScene:
    """Embree's scene with every hit distance moved by a few float32 ulps, as another CPU's
    intersection kernels return them."""

    def __init__(self, scene: o3d.t.geometry.RaycastingScene) -> None:
        self._scene = scene

    def cast_rays(self, rays: o3d.core.Tensor) -> dict[str, o3d.core.Tensor]:
        hits = self._scene.cast_rays(rays)
        t = hits["t_hit"].numpy()
        nudged = np.where(np.isfinite(t), t * np.float32(1.0 + 3e-7), t).astype(np.float32)
        return {"t_hit": o3d.core.Tensor.from_numpy(nudged), "primitive_ids": hits["primitive_ids"]}


def test_depth_does_not_depend_on_embree_distances() -> None:
    cfg = CameraConfig(max_range_m=10.0)
    cam = camera(cfg)
    pose = Pose(np.array([1.3, 1.7, 1.1]), 0.4)
    plain = cam.render(pose).depth
    cam._scene = _NudgedScene(cam._scene)
    assert np.array_equal(cam.render(pose).depth, plain)
    # ... and the distance from the triangles' planes is at least as close to the truth.
    assert np.allclose(plain, analytic_depth(cfg, pose.position, pose.yaw), rtol=0.0, atol=1e-5)


def _numpy_depth(cam: DepthCamera, pose: Pose, stride: int) -> npt.NDArray[np.float32]:
    """The depth image as whole-array NumPy passes compute it (the formulation the compiled
    loop must reproduce to the bit): plane distances in float64, z-depth in float32, the
    range mask compared in float32."""
    cfg = cam.config
    _, inv_norm = cam._directions(stride)
    rays = cam.rays(pose, stride)
    hits = cam._scene.cast_rays(o3d.core.Tensor(rays))
    prims, t_embree = hits["primitive_ids"].numpy(), hits["t_hit"].numpy()
    t = np.full(prims.shape, np.inf)
    hit = np.flatnonzero(prims != np.uint32(0xFFFFFFFF))
    ids = prims[hit].astype(np.int64)
    n, offsets = cam._normals[ids], cam._offsets[ids]
    o, d = rays[hit, :3].astype(np.float64), rays[hit, 3:].astype(np.float64)
    denom = n[:, 0] * d[:, 0] + n[:, 1] * d[:, 1] + n[:, 2] * d[:, 2]
    num = offsets - (n[:, 0] * o[:, 0] + n[:, 1] * o[:, 1] + n[:, 2] * o[:, 2])
    steep = np.abs(denom) > 1e-6
    t[hit] = np.where(steep, num / np.where(steep, denom, 1.0), t_embree[hit])
    depth = (t * inv_norm).astype(np.float32)
    depth[(depth > cfg.max_range_m) | (depth < cfg.min_range_m)] = np.nan
    return depth.reshape(-(-cfg.height // stride), -(-cfg.width // stride))


@pytest.mark.parametrize("stride", [1, 2])
def test_depth_is_the_numpy_formulation_to_the_bit(stride: int) -> None:
    # A cluttered scene (random triangles inside the box, many seen edge-on), a near range
    # limit that cuts through it, poses all over: every pixel, NaNs included, is equal.
    rng = np.random.default_rng(11)
    vertices, triangles = box_mesh()
    soup = rng.uniform(0.2, 3.8, size=(600, 3)) * np.array([1.0, 1.0, 0.75])
    flat = soup.reshape(-1, 3, 3)
    flat[::3, :, 2] = flat[::3, :1, 2]  # a third lie in horizontal planes: grazing at eye level
    all_vertices = np.vstack([vertices, soup])
    all_triangles = np.vstack([triangles, len(vertices) + np.arange(600).reshape(-1, 3)])
    cam = DepthCamera(all_vertices, all_triangles.astype(np.int32),
                      CameraConfig(min_range_m=0.35, max_range_m=2.5))
    finite = missing = 0
    for _ in range(20):
        pose = Pose(rng.uniform([0.3, 0.3, 0.3], [3.7, 3.7, 2.7]), float(rng.uniform(-4, 4)))
        rendered = cam.render(pose, 0.0, stride).depth
        expected = _numpy_depth(cam, pose, stride)
        assert rendered.dtype == np.float32
        assert np.array_equal(rendered, expected, equal_nan=True)
        finite += int(np.isfinite(expected).sum())
        missing += int(np.isnan(expected).sum())
    assert finite > 1000 and missing > 1000


@pytest.mark.parametrize("stride", [1, 2, 3])
def test_rays_are_numpys_rounding_of_the_rotated_directions(stride: int) -> None:
    cam = camera(ODD)
    rng = np.random.default_rng(5)
    for _ in range(20):
        pose = Pose(rng.uniform(-50.0, 50.0, 3) * rng.choice([1e-3, 1.0, 1e3]),
                    float(rng.uniform(-np.pi, np.pi)))
        unit_dirs = cam._unit_directions(stride) @ cam.world_from_optical(pose.yaw).T
        expected = np.empty((unit_dirs.shape[0], 6), dtype=np.float32)
        expected[:, :3] = pose.position
        expected[:, 3:] = unit_dirs
        rays = cam.rays(pose, stride)
        assert rays.dtype == np.float32 and rays.shape == expected.shape
        assert np.array_equal(rays.view(np.uint32), expected.view(np.uint32))
