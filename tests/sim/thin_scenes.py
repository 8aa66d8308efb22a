"""Test scenes with surfaces thinner than a voxel, and scripted camera passes through them.

`rod_hall()` hangs WAREHOUSE's 2 cm lamp rods in a hall of 0.2 m voxels; `flyby_pass` flies
past one of them.

`thin_room()` is a 10 x 12 x 3 m room (0.1 m voxels) split by a wall with a 1.0 m and a 0.8 m
door; in front of the wall stand 5 cm rails, 2 cm wires and 4 cm plates at several angles, one of
them edge-on to the camera at its height. Every large surface (floor, ceiling, walls, door jambs)
lies on a plane through voxel centres, so depth noise of a few centimetres keeps their returns in
their own voxels and the free span of a door is exactly its width in voxels, less one.

`fly_pass` renders a scripted list of poses with `sim.camera.DepthCamera`, adds depth noise as
`sim.sensing.Sensing` does and fuses the frames into an `OccupancyMap` at the default preset's
stride, calling back after every frame.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from areas.area import Area, AreaInfo, StartPose
from areas.primitives import Mesh, boxes, concat, cylinders, oriented_boxes, wall
from sim.camera import CameraConfig, DepthCamera
from sim.config import preset
from sim.geometry import Pose
from sim.noise import DepthNoiseConfig, add_depth_noise
from sim.occupancy import OccupancyConfig, OccupancyMap
from sim.open3d_any import o3d

IndexArray = npt.NDArray[np.int64]

VOXEL = 0.1
BOUNDS_MIN = np.array([0.0, 0.0, 0.0])
BOUNDS_MAX = np.array([10.0, 12.0, 3.0])
FLOOR_Z = 0.05
CEILING_Z = 2.95
# The wall between the two rooms: faces at y = 8.05 and 8.25, doors 2.0 m high.
WALL_NEAR_Y = 8.05
WALL_FAR_Y = 8.25
DOOR_TOP_Z = 2.05
CAMERA_Z = 1.0  # the gallery pass: the desk top is edge-on at this height
DOOR_PASS_Z = 1.05  # the door passes fly through voxel centres


@dataclass(frozen=True)
class ThinPart:
    """One thin solid of the scene.

    Attributes:
        name: unique in the scene.
        kind: "rail", "wire" or "plate".
        thickness_m: its smallest dimension.
        mesh: its closed surface.
    """

    name: str
    kind: str
    thickness_m: float
    mesh: Mesh

    def surface_voxels(self, origin: npt.ArrayLike, voxel_size: float,
                       shape: tuple[int, int, int], spacing_m: float = 0.003) -> IndexArray:
        """(K, 3) voxels that hold some of the part's surface, from samples about `spacing_m`
        apart on its triangles (a voxel holding less surface than a sample's share may be
        left out)."""
        rng = np.random.default_rng(0)
        tri = self.mesh.vertices[self.mesh.triangles]  # (F, 3, 3)
        area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
        counts = np.maximum(np.ceil(area / spacing_m**2).astype(np.int64), 3)
        which = np.repeat(np.arange(len(tri)), counts)
        u, v = rng.random((2, len(which)))
        flip = u + v > 1.0
        u[flip], v[flip] = 1.0 - u[flip], 1.0 - v[flip]
        t = tri[which]
        points = t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])
        idx = np.floor((points - np.asarray(origin)) / voxel_size).astype(np.int64)
        inside = np.all((idx >= 0) & (idx < np.array(shape)), axis=1)
        return np.unique(idx[inside], axis=0)


@dataclass(frozen=True)
class Door:
    """An opening in the dividing wall, from x0 to x1, floor to `DOOR_TOP_Z`."""

    name: str
    x0: float
    x1: float

    @property
    def width_m(self) -> float:
        return self.x1 - self.x0

    @property
    def centre_x(self) -> float:
        return 0.5 * (self.x0 + self.x1)


DOORS = (Door("door_1.0m", 2.05, 3.05), Door("door_0.8m", 7.05, 7.85))


def door_free_voxels(width_m: float, voxel_size: float = VOXEL) -> int:
    """Free voxels across a door whose jambs lie on planes through voxel centres: each jamb's
    surface voxel is occupied, so the door's width in voxels less one."""
    return round(width_m / voxel_size) - 1


def free_run_needed(radius_m: float, voxel_size: float = VOXEL) -> int:
    """The fewest free voxels across an opening that leave a traversable centre under the
    clearance rule (`sim.clearance`: a centre at least `radius_m` from every obstacle cube):
    the centre of the m-th free voxel (from 0) is m + 1/2 voxels from one jamb's cube, so
    m >= radius - 1/2 from both jambs."""
    m = math.ceil(radius_m / voxel_size - 0.5 - 1e-9)
    return 2 * m + 1


def _plate(name: str, centre: tuple[float, float, float], yaw: float, pitch: float,
           size: tuple[float, float], thickness: float = 0.04) -> ThinPart:
    """A plate `size` (length, height) of `thickness`: its length runs along yaw, its normal is
    horizontal, at yaw + 90 degrees, tilted up by `pitch`."""
    cy, sy, cp, sp = math.cos(yaw), math.sin(yaw), math.cos(pitch), math.sin(pitch)
    along = np.array([cy, sy, 0.0])
    normal = np.array([-sy * cp, cy * cp, sp])
    up = np.cross(normal, along)
    axes = np.stack([along, up, normal])[None]
    half = np.array([[size[0] / 2.0, size[1] / 2.0, thickness / 2.0]])
    return ThinPart(name, "plate", thickness, oriented_boxes(np.array([centre]), axes, half))


def thin_parts() -> list[ThinPart]:
    """The rails, wires and plates standing in front of the dividing wall."""
    rail_r, wire_r = 0.025, 0.01
    parts = [
        ThinPart("handrail", "rail", 2 * rail_r,
                 cylinders([[3.7, 6.5, 0.9]], [[6.3, 6.5, 0.9]], rail_r)),
        ThinPart("rail_posts", "rail", 2 * rail_r,
                 cylinders([[3.7, 6.5, FLOOR_Z], [6.3, 6.5, FLOOR_Z]],
                           [[3.7, 6.5, 0.9], [6.3, 6.5, 0.9]], rail_r)),
        ThinPart("wire_vertical", "wire", 2 * wire_r,
                 cylinders([[4.2, 5.8, FLOOR_Z]], [[4.2, 5.8, CEILING_Z]], wire_r)),
        ThinPart("wire_diagonal", "wire", 2 * wire_r,
                 cylinders([[5.6, 5.4, FLOOR_Z]], [[6.0, 5.9, CEILING_Z]], wire_r)),
        ThinPart("wire_horizontal", "wire", 2 * wire_r,
                 cylinders([[3.7, 6.8, 1.4]], [[6.3, 6.8, 1.4]], wire_r)),
        # A desk top whose front edge faces the camera, exactly edge-on at the camera's height.
        ThinPart("desk_edge_on", "plate", 0.04,
                 boxes([4.4, 5.0, CAMERA_Z - 0.02], [5.6, 5.7, CAMERA_Z + 0.02])),
        # A vertical plate in the plane the gallery pass flies in: edge-on the whole way.
        _plate("plate_vertical_edge_on", (5.0, 6.1, 1.65), math.pi / 2, 0.0, (0.8, 0.6)),
        _plate("plate_grazing_10deg", (3.9, 5.2, 1.5), math.radians(80.0), 0.0, (0.8, 0.6)),
        _plate("plate_yaw_45deg", (6.1, 5.3, 1.5), math.radians(45.0), 0.0, (0.6, 0.6)),
        _plate("plate_facing", (4.6, 6.9, 2.1), 0.0, 0.0, (0.6, 0.5)),
        _plate("plate_sloping_30deg", (5.6, 6.3, 2.3), 0.0, math.radians(60.0), (0.7, 0.6)),
    ]
    return parts


def _room() -> Mesh:
    lo, hi = BOUNDS_MIN - 0.3, BOUNDS_MAX + 0.3
    shell = boxes(
        [[lo[0], lo[1], lo[2]], [lo[0], lo[1], CEILING_Z],
         [lo[0], lo[1], lo[2]], [9.95, lo[1], lo[2]],
         [lo[0], lo[1], lo[2]], [lo[0], 11.95, lo[2]]],
        [[hi[0], hi[1], FLOOR_Z], [hi[0], hi[1], hi[2]],
         [0.05, hi[1], hi[2]], [hi[0], hi[1], hi[2]],
         [hi[0], 0.05, hi[2]], [hi[0], hi[1], hi[2]]],
    )
    openings = [(d.x0, FLOOR_Z, d.x1, DOOR_TOP_Z) for d in DOORS]
    divider = wall(0, 0.05, 9.95, 0.5 * (WALL_NEAR_Y + WALL_FAR_Y), WALL_FAR_Y - WALL_NEAR_Y,
                   FLOOR_Z, CEILING_Z, openings)
    return concat([shell, divider])


def thin_room() -> tuple[Area, list[ThinPart]]:
    """The scene as an `Area` on a 0.1 m grid, and its thin parts."""
    parts = thin_parts()
    mesh = concat([_room(), *(p.mesh for p in parts)])
    area = Area(
        name="thin-room",
        vertices=np.ascontiguousarray(mesh.vertices, dtype=np.float64),
        triangles=np.ascontiguousarray(mesh.triangles, dtype=np.int32),
        bounds_min=BOUNDS_MIN.copy(),
        bounds_max=BOUNDS_MAX.copy(),
        start=StartPose(position=np.array([5.0, 1.0, CAMERA_Z]), yaw=math.pi / 2),
        plateau_s=60.0,
        voxel_size=VOXEL,
        info=AreaInfo(title="Thin structures", rooms=2, levels=1, complexity="test",
                      indoor=True),
    )
    return area, parts


def _line(a: tuple[float, float, float], b: tuple[float, float, float], yaw: float,
          steps: int, sweep_rad: float = 0.0) -> list[Pose]:
    """`steps` poses from a to b (b included), the yaw swinging by ±`sweep_rad` about `yaw`."""
    pa, pb = np.array(a), np.array(b)
    out = []
    for s in range(1, steps + 1):
        t = s / steps
        swing = sweep_rad * math.sin(2.0 * math.pi * s / 10.0)
        out.append(Pose(pa + t * (pb - pa), yaw + swing))
    return out


def gallery_pass() -> list[Pose]:
    """Toward the thin parts along x = 5: 40 frames 4.5-5.5 m from the nearest (the distance at
    which passing rays outnumber hits), then an approach to 1 m and a sideways pass, at 0.2 m per
    fused frame or slower (1 m/s at 5 Hz)."""
    north = math.pi / 2
    z = CAMERA_Z
    poses = _line((5.0, 0.3, z), (5.0, 0.3, z), north, 1)
    poses += _line((5.0, 0.3, z), (5.0, 0.5, z), north, 20, sweep_rad=0.35)
    poses += _line((5.0, 0.5, z), (5.0, 0.3, z), north, 20, sweep_rad=0.35)
    poses += _line((5.0, 0.3, z), (5.0, 4.0, z), north, 20, sweep_rad=0.15)
    poses += _line((5.0, 4.0, z), (3.6, 4.0, z), north, 8)
    poses += _line((3.6, 4.0, z), (6.4, 4.0, z), north, 14)
    return poses


def door_pass(door: Door) -> list[Pose]:
    """Toward a door along its centre line, from 5 m to 1 m of the wall, looking through it."""
    north = math.pi / 2
    x, z = door.centre_x, DOOR_PASS_Z
    poses = _line((x, WALL_NEAR_Y - 5.0, z), (x, WALL_NEAR_Y - 5.0, z), north, 1)
    poses += _line((x, WALL_NEAR_Y - 5.0, z), (x, WALL_NEAR_Y - 1.0, z), north, 20,
                   sweep_rad=0.25)
    poses += _line((x, WALL_NEAR_Y - 1.0, z), (x, WALL_NEAR_Y - 1.0, z), north, 10,
                   sweep_rad=0.25)
    return poses


# The rod hall: lamp rods as WAREHOUSE hangs its lamps (`areas/warehouse.py`: 2 cm across, six
# sides, 1 m long) in 0.2 m voxels, where a rod fills a tenth of its voxels' width.
ROD_VOXEL = 0.2
ROD_RADIUS = 0.01
ROD_Z = (1.5, 2.5)
# Through the middle of its voxels, along an x face, along a y face, along a voxel edge.
RODS_XY = ((4.5, 4.5), (8.0, 4.5), (4.5, 8.0), (8.0, 8.0))
FLYBY_Z = 2.0


def rod_hall() -> Area:
    """A 12 x 12 x 4 m hall (0.2 m voxels) with four hanging rods, each above a lamp shade."""
    size = np.array([12.0, 12.0, 4.0])
    lo, hi = -0.3 * np.ones(3), size + 0.3
    shell = boxes(
        [[lo[0], lo[1], lo[2]], [lo[0], lo[1], 3.9], [lo[0], lo[1], lo[2]],
         [11.9, lo[1], lo[2]], [lo[0], lo[1], lo[2]], [lo[0], 11.9, lo[2]]],
        [[hi[0], hi[1], 0.1], [hi[0], hi[1], hi[2]], [0.1, hi[1], hi[2]],
         [hi[0], hi[1], hi[2]], [hi[0], 0.1, hi[2]], [hi[0], hi[1], hi[2]]],
    )
    rods = cylinders([(x, y, ROD_Z[0]) for x, y in RODS_XY],
                     [(x, y, ROD_Z[1]) for x, y in RODS_XY], ROD_RADIUS, 6)
    shades = boxes([(x - 0.3, y - 0.3, ROD_Z[0] - 0.35) for x, y in RODS_XY],
                   [(x + 0.3, y + 0.3, ROD_Z[0]) for x, y in RODS_XY])
    mesh = concat([shell, rods, shades])
    return Area(
        name="rod-hall",
        vertices=np.ascontiguousarray(mesh.vertices, dtype=np.float64),
        triangles=np.ascontiguousarray(mesh.triangles, dtype=np.int32),
        bounds_min=np.zeros(3), bounds_max=size,
        start=StartPose(position=np.array([1.0, 1.0, FLYBY_Z]), yaw=0.0),
        plateau_s=60.0, voxel_size=ROD_VOXEL,
        info=AreaInfo(title="Rod hall", rooms=1, levels=1, complexity="test", indoor=True),
    )


def rod_voxels(area: Area, x: float, y: float) -> IndexArray:
    """(K, 3) the voxels holding some of a rod's cross-section (one to four per height)."""
    zs = np.arange(ROD_Z[0] + 0.01, ROD_Z[1], 0.02)
    offsets = [(dx, dy) for dx in (-0.9, 0.9) for dy in (-0.9, 0.9)]
    points = np.concatenate([np.stack([np.full_like(zs, x + dx * ROD_RADIUS),
                                       np.full_like(zs, y + dy * ROD_RADIUS), zs], axis=1)
                             for dx, dy in offsets])
    idx = np.floor((points - area.bounds_min) / area.voxel_size).astype(np.int64)
    return np.unique(idx, axis=0)


def flyby_pass(rod: tuple[float, float], heading: float, lateral_m: float) -> list[Pose]:
    """Past a rod at 0.3 m per fused frame (1.5 m/s at 5 Hz), looking along the motion, its
    closest approach `lateral_m` from the rod's axis: from 4.5 m before that point to 1.5 m
    after."""
    along = np.array([math.cos(heading), math.sin(heading), 0.0])
    side = np.array([-along[1], along[0], 0.0])
    closest = np.array([rod[0], rod[1], FLYBY_Z]) + lateral_m * side
    return [Pose(closest + s * along, heading) for s in np.arange(-4.5, 1.5 + 1e-9, 0.3)]


def new_map(area: Area, config: OccupancyConfig | None = None) -> OccupancyMap:
    return OccupancyMap(area.bounds_min, area.grid_shape, area.voxel_size, config)


def free_space_voxels(area: Area) -> npt.NDArray[np.bool_]:
    """(nx, ny, nz) True on voxels whose cube holds no surface and lies outside every solid:
    the centre is outside the (closed) mesh and farther than half a voxel diagonal from it. An
    occupied one is depth-noise speckle."""
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(area.vertices.astype(np.float32)),
                        o3d.core.Tensor(area.triangles.astype(np.uint32)))
    idx = np.indices(area.grid_shape).reshape(3, -1).T
    centres = o3d.core.Tensor((area.bounds_min + (idx + 0.5) * area.voxel_size)
                              .astype(np.float32))
    distance = scene.compute_distance(centres).numpy()
    inside = scene.compute_occupancy(centres).numpy() > 0
    free = (distance > 0.5 * math.sqrt(3.0) * area.voxel_size) & ~inside
    return np.asarray(free.reshape(area.grid_shape), dtype=np.bool_)


def fly_pass(
    area: Area,
    occupancy: OccupancyMap,
    poses: Iterable[Pose],
    seed: int = 0,
    noise: DepthNoiseConfig | None = None,
    camera: DepthCamera | None = None,
    after_frame: Callable[[int, Pose], None] | None = None,
) -> DepthCamera:
    """Fuse one depth frame per pose into `occupancy` at the default preset's pixel stride, with
    the default depth noise (or `noise`) drawn from `seed`; returns the camera."""
    cfg = preset("default")
    cam = camera or DepthCamera(area.vertices, area.triangles, CameraConfig())
    rng = np.random.default_rng(seed)
    stride = cfg.occupancy_pixel_stride
    for n, pose in enumerate(poses):
        depth = add_depth_noise(cam.render(pose, stride=stride).depth, noise or cfg.depth_noise,
                                rng)
        ends, hit = cam.back_project(depth, pose, stride)
        occupancy.integrate(pose.position, ends, hit)
        if after_frame is not None:
            after_frame(n, pose)
    return cam
