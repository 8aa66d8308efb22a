"""Depth camera rendered by ray casting the area mesh with Open3D (Embree on the CPU).

The camera sits at the vehicle centre, level, looking along body +x. Depth is z-depth (distance
along the optical axis), not ray length, like a real depth sensor.

Embree picks its intersection kernels by CPU (SSE, AVX2, AVX-512) and their hit distances
differ in the last bit: on one frame of MAZE, 3,015 of 19,200 rays, by up to 1e-6 m, and a
flight then takes other branches (`docs/notes/2026-12-embree-kernels.md`). The triangle each
ray hits is the same on every kernel, so Embree only says *which* triangle; the distance along
the ray is computed again here from that triangle's plane, in float64 with plain NumPy
arithmetic, which every machine does alike.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numba
import numpy as np
import numpy.typing as npt
from pydantic import BaseModel, ConfigDict, Field

from sim.geometry import FloatArray, Pose, yaw_matrix
from sim.open3d_any import o3d

# Embree's "no hit" primitive id.
_NO_HIT = np.uint32(0xFFFFFFFF)
# Below this |cos| between a ray and a triangle's normal the plane formula is ill-conditioned;
# such grazing hits keep Embree's distance.
_GRAZING_COS = 1e-6

# Optical frame (x right, y down, z forward) expressed in the body frame (x forward, y left, z up).
BODY_FROM_OPTICAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


class CameraConfig(BaseModel):
    """Depth camera model; defaults are the benchmark's sensor."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    fov_h_deg: float = Field(90.0, gt=0.0, lt=180.0)
    fov_v_deg: float = Field(73.7, gt=0.0, lt=180.0)
    width: int = Field(160, ge=2, le=4096)
    height: int = Field(120, ge=2, le=4096)
    max_range_m: float = Field(5.0, gt=0.0)
    min_range_m: float = Field(0.1, ge=0.0)
    rate_hz: float = Field(20.0, gt=0.0)

    def intrinsic_matrix(self) -> FloatArray:
        """(3, 3) pinhole matrix K, pixel centres at integer coordinates + 0.5."""
        fx = (self.width / 2.0) / np.tan(np.radians(self.fov_h_deg) / 2.0)
        fy = (self.height / 2.0) / np.tan(np.radians(self.fov_v_deg) / 2.0)
        return np.array([[fx, 0.0, self.width / 2.0], [0.0, fy, self.height / 2.0], [0, 0, 1.0]])


@dataclass(frozen=True)
class DepthFrame:
    """One depth image.

    Attributes:
        time: simulated seconds.
        depth: (H, W) float32 z-depth in metres; NaN where nothing is within range.
        pose: the pose the image was rendered from (true pose).
    """

    time: float
    depth: npt.NDArray[np.float32]
    pose: Pose


class DepthCamera:
    """Renders z-depth images of a triangle mesh."""

    def __init__(
        self,
        vertices: FloatArray,
        triangles: npt.NDArray[np.int32],
        config: CameraConfig | None = None,
    ) -> None:
        self.config = config or CameraConfig()
        self._scene: Any = o3d.t.geometry.RaycastingScene()
        self._scene.add_triangles(
            o3d.core.Tensor(np.ascontiguousarray(vertices, dtype=np.float32)),
            o3d.core.Tensor(np.ascontiguousarray(triangles, dtype=np.uint32)),
        )
        self._normals, self._offsets = _triangle_planes(
            np.asarray(vertices, dtype=np.float64), np.asarray(triangles, dtype=np.int64))
        k = self.config.intrinsic_matrix()
        u, v = np.meshgrid(
            np.arange(self.config.width) + 0.5, np.arange(self.config.height) + 0.5
        )
        # Unnormalised optical-frame directions with z = 1, so a z-depth scales them to points.
        self._pixel_dirs_optical = np.stack(
            [(u - k[0, 2]) / k[0, 0], (v - k[1, 2]) / k[1, 1], np.ones_like(u)], axis=-1
        ).reshape(-1, 3)
        self._inv_norm = 1.0 / np.linalg.norm(self._pixel_dirs_optical, axis=1)
        self._strided: dict[int, tuple[FloatArray, FloatArray]] = {
            1: (self._pixel_dirs_optical, self._inv_norm)
        }
        self._unit: dict[int, FloatArray] = {}

    def close(self) -> None:
        """Let go of the scene (Embree's copy of the mesh and its hierarchy: 65 MiB on FACILITY
        C's 580,000 triangles) and the triangles' planes; the camera renders no more."""
        self._scene = None
        self._normals = self._offsets = np.zeros(0)

    @property
    def closed(self) -> bool:
        return self._scene is None

    def _live_scene(self) -> Any:
        if self._scene is None:
            raise RuntimeError("the camera is closed")
        return self._scene

    def distance_to_surface(self, point: FloatArray) -> float:
        """Distance in metres from `point` (3,) to the nearest scene surface."""
        return float(self.distance_to_surface_many(np.asarray(point).reshape(1, 3))[0])

    def distance_to_surface_many(self, points: npt.NDArray[np.floating]) -> FloatArray:
        """(N,) distances in metres from points (N, 3) to the nearest scene surface."""
        query = o3d.core.Tensor(np.ascontiguousarray(points, dtype=np.float32).reshape(-1, 3))
        return np.asarray(self._live_scene().compute_distance(query).numpy(), dtype=np.float64)

    def world_from_optical(self, yaw: float) -> FloatArray:
        """(3, 3) rotation taking optical-frame vectors to world vectors."""
        return yaw_matrix(yaw) @ BODY_FROM_OPTICAL

    def _directions(self, stride: int) -> tuple[FloatArray, FloatArray]:
        """Optical-frame directions (z = 1) and their inverse norms of every `stride`-th row and
        column, C order."""
        if stride not in self._strided:
            cfg = self.config
            keep = np.zeros((cfg.height, cfg.width), dtype=bool)
            keep[::stride, ::stride] = True
            flat = keep.reshape(-1)
            self._strided[stride] = (self._pixel_dirs_optical[flat], self._inv_norm[flat])
        return self._strided[stride]

    def _unit_directions(self, stride: int) -> FloatArray:
        """(P, 3) unit optical-frame directions of the pixels kept at `stride`."""
        if stride not in self._unit:
            dirs, inv_norm = self._directions(stride)
            self._unit[stride] = dirs * inv_norm[:, None]
        return self._unit[stride]

    def rays(self, pose: Pose, stride: int = 1) -> npt.NDArray[np.float32]:
        """(P, 6) float32 rays Embree casts for the image from `pose` at `stride`: the camera
        centre and each kept pixel's unit direction, world frame, C order."""
        unit_dirs = self._unit_directions(stride) @ self.world_from_optical(pose.yaw).T
        return _ray_rows(np.asarray(pose.position, dtype=np.float64), unit_dirs)

    def render(self, pose: Pose, time: float = 0.0, stride: int = 1) -> DepthFrame:
        """Ray-cast one depth image from `pose`; with `stride` > 1 only every stride-th row and
        column (an image of ceil(H / stride) x ceil(W / stride) pixels)."""
        cfg = self.config
        _, inv_norm = self._directions(stride)
        rays = self.rays(pose, stride)
        hits = self._live_scene().cast_rays(o3d.core.Tensor(rays))
        depth = _z_depths(rays, hits["primitive_ids"].numpy(), hits["t_hit"].numpy(),
                          self._normals, self._offsets, inv_norm,
                          np.float32(cfg.min_range_m), np.float32(cfg.max_range_m))
        shape = (-(-cfg.height // stride), -(-cfg.width // stride))
        return DepthFrame(time=time, depth=depth.reshape(shape), pose=pose)

    def back_project(
        self, depth: npt.NDArray[np.float32], pose: Pose, stride: int = 1
    ) -> tuple[FloatArray, npt.NDArray[np.bool_]]:
        """World endpoints of every pixel's ray and whether it returned.

        Args:
            depth: an image rendered with the same `stride`.

        Returns:
            endpoints: (P, 3) world points; pixels without a return end at the maximum range.
            hit: (P,) True where the pixel measured a surface.
        """
        dirs, _ = self._directions(stride)
        z = depth.reshape(-1).astype(np.float64)
        hit = np.isfinite(z)
        z = np.where(hit, z, self.config.max_range_m)
        points_optical = dirs * z[:, None]
        endpoints = points_optical @ self.world_from_optical(pose.yaw).T + pose.position
        return endpoints, hit


@numba.njit(cache=True)
def _ray_rows(origin: FloatArray, unit_dirs: FloatArray) -> npt.NDArray[np.float32]:
    """(P, 6) float32 rows of `origin` (3,) and each of `unit_dirs` (P, 3), rounded to float32
    as NumPy's assignment rounds them, in one pass (NumPy's two strided assignments cost
    more than the rotation before them)."""
    out = np.empty((unit_dirs.shape[0], 6), dtype=np.float32)
    o0, o1, o2 = np.float32(origin[0]), np.float32(origin[1]), np.float32(origin[2])
    for i in range(unit_dirs.shape[0]):
        out[i, 0], out[i, 1], out[i, 2] = o0, o1, o2
        out[i, 3] = np.float32(unit_dirs[i, 0])
        out[i, 4] = np.float32(unit_dirs[i, 1])
        out[i, 5] = np.float32(unit_dirs[i, 2])
    return out


@numba.njit(cache=True)
def _z_depths(rays: npt.NDArray[np.float32], prims: npt.NDArray[np.uint32],
              t_embree: npt.NDArray[np.float32], normals: FloatArray, offsets: FloatArray,
              inv_norm: FloatArray, min_range: np.float32, max_range: np.float32
              ) -> npt.NDArray[np.float32]:
    """(N,) float32 z-depth of each ray, NaN outside [min_range, max_range] (compared in
    float32, as NumPy compares a float32 image with a Python float) or without a hit.

    The distance along each ray (N, 6: origin, unit direction) is taken to the plane of the
    triangle Embree hit (`normals` (F, 3) and `offsets` (F,)), in float64 and in a fixed order
    of operations, so every machine computes the same bits; grazing hits keep Embree's
    distance. Times `inv_norm` (N,) it is the z-depth.
    """
    out = np.empty(prims.shape[0], dtype=np.float32)
    for r in range(prims.shape[0]):
        t = np.inf
        if prims[r] != _NO_HIT:
            f = np.int64(prims[r])
            n0, n1, n2 = normals[f, 0], normals[f, 1], normals[f, 2]
            o0, o1, o2 = np.float64(rays[r, 0]), np.float64(rays[r, 1]), np.float64(rays[r, 2])
            d0, d1, d2 = np.float64(rays[r, 3]), np.float64(rays[r, 4]), np.float64(rays[r, 5])
            denom = n0 * d0 + n1 * d1 + n2 * d2
            if abs(denom) > _GRAZING_COS:
                t = (offsets[f] - (n0 * o0 + n1 * o1 + n2 * o2)) / denom
            else:
                t = np.float64(t_embree[r])
        depth = np.float32(t * inv_norm[r])
        out[r] = np.nan if depth > max_range or depth < min_range else depth
    return out


def _triangle_planes(vertices: FloatArray, triangles: npt.NDArray[np.int64]
                     ) -> tuple[FloatArray, FloatArray]:
    """Unit normals (F, 3) and offsets (F,) of the triangles' planes (n . x = offset); zero
    normals for degenerate triangles."""
    v0, v1, v2 = (vertices[triangles[:, i]] for i in range(3))
    e1, e2 = v1 - v0, v2 - v0
    n = np.stack([e1[:, 1] * e2[:, 2] - e1[:, 2] * e2[:, 1],
                  e1[:, 2] * e2[:, 0] - e1[:, 0] * e2[:, 2],
                  e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]], axis=1)
    length = np.sqrt(n[:, 0] * n[:, 0] + n[:, 1] * n[:, 1] + n[:, 2] * n[:, 2])
    n = n / np.where(length > 0.0, length, 1.0)[:, None]
    return n, n[:, 0] * v0[:, 0] + n[:, 1] * v0[:, 1] + n[:, 2] * v0[:, 2]
