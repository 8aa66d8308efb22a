"""Thumbnail images of an area for the web gallery: a top view and a perspective view.

Rendered by ray casting the mesh with Open3D (as the simulated camera does), shaded by the angle
to a fixed light and tinted by height, and written as 8-bit RGB PNG with zlib (no imaging
dependency). Indoor areas are shown without their roof: the top view casts from just under the
highest ceiling and the perspective view leaves out the triangles lying entirely in the top
0.3 m, so one sees into the top storey.
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np
import numpy.typing as npt
import open3d as o3d

from areas.area import Area
from areas.cache import cache_dir

Image = npt.NDArray[np.uint8]
FloatArray = npt.NDArray[np.float64]

ROOF_CUT = 0.3
LIGHT = np.array([0.35, 0.5, 0.8]) / np.linalg.norm([0.35, 0.5, 0.8])
BACKGROUND = np.array([236, 240, 245], dtype=np.float64)


def write_png(path: Path, image: Image) -> None:
    """Write an (H, W, 3) uint8 RGB image as a PNG file."""
    h, w, _ = image.shape
    raw = b"".join(b"\x00" + image[row].tobytes() for row in range(h))

    def chunk(kind: bytes, data: bytes) -> bytes:
        body = kind + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body))

    header = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header)
                     + chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b""))


def _scene(area: Area) -> o3d.t.geometry.RaycastingScene:
    tri = area.triangles
    if area.info.indoor:
        top = area.vertices[tri, 2].min(axis=1)
        tri = tri[top < area.bounds_max[2] - ROOF_CUT]
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor.from_numpy(np.ascontiguousarray(area.vertices, dtype=np.float32)),
        o3d.core.Tensor.from_numpy(np.ascontiguousarray(tri, dtype=np.uint32)),
    )
    return scene


def _shade(area: Area, scene: o3d.t.geometry.RaycastingScene, rays: FloatArray,
           shape: tuple[int, int]) -> Image:
    """Cast (H * W, 6) rays and shade the hits: Lambert on a fixed light, tinted by height."""
    hits = scene.cast_rays(o3d.core.Tensor.from_numpy(rays.astype(np.float32)))
    t = hits["t_hit"].numpy().astype(np.float64)
    normal = hits["primitive_normals"].numpy().astype(np.float64)
    hit = np.isfinite(t)
    point_z = rays[:, 2] + np.where(hit, t, 0.0) * rays[:, 5]
    height = np.clip((point_z - area.bounds_min[2]) / max(float(area.extent[2]), 1e-6), 0.0, 1.0)
    light = 0.35 + 0.65 * np.abs(normal @ LIGHT)
    # Low surfaces blue-grey, high ones warm: height reads at a glance from the top view.
    low, high = np.array([90.0, 120.0, 170.0]), np.array([240.0, 190.0, 120.0])
    colour = (low[None, :] * (1 - height[:, None]) + high[None, :] * height[:, None])
    rgb = np.where(hit[:, None], colour * light[:, None], BACKGROUND[None, :])
    return np.clip(rgb, 0, 255).astype(np.uint8).reshape(*shape, 3)


def render_top(area: Area, max_side: int = 512) -> Image:
    """(H, W, 3) orthographic view from above; +x to the right, +y up the image."""
    ext = area.extent
    scale = max_side / float(max(ext[0], ext[1]))
    w, h = max(1, round(ext[0] * scale)), max(1, round(ext[1] * scale))
    xs = area.bounds_min[0] + (np.arange(w) + 0.5) / scale
    ys = area.bounds_max[1] - (np.arange(h) + 0.5) / scale
    gx, gy = np.meshgrid(xs, ys)
    top = area.bounds_max[2] - ROOF_CUT if area.info.indoor else area.bounds_max[2] + 1.0
    rays = np.zeros((h * w, 6))
    rays[:, 0], rays[:, 1], rays[:, 2] = gx.ravel(), gy.ravel(), top
    rays[:, 5] = -1.0
    return _shade(area, _scene(area), rays, (h, w))


def render_perspective(area: Area, width: int = 640, height: int = 480,
                       fov_deg: float = 50.0) -> Image:
    """(H, W, 3) view from above a corner of the bounds towards the centre."""
    centre = (area.bounds_min + area.bounds_max) / 2.0
    ext = area.extent
    eye = centre + np.array([-0.9 * ext[0], -1.1 * ext[1], 0.0])
    eye[2] = area.bounds_min[2] + 0.9 * float(np.linalg.norm(ext[:2])) + 0.5 * ext[2]
    forward = centre - eye
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    f = (width / 2.0) / np.tan(np.radians(fov_deg) / 2.0)
    u = (np.arange(width) + 0.5 - width / 2.0) / f
    v = (np.arange(height) + 0.5 - height / 2.0) / f
    gu, gv = np.meshgrid(u, v)
    d = forward[None, :] + gu.ravel()[:, None] * right[None, :] - gv.ravel()[:, None] * up[None, :]
    d /= np.linalg.norm(d, axis=1)[:, None]
    rays = np.concatenate([np.broadcast_to(eye, d.shape), d], axis=1)
    return _shade(area, _scene(area), rays, (height, width))


def thumbnail_paths(area: Area) -> tuple[Path, Path]:
    """Cache files of the top and perspective thumbnails of ``area``."""
    stem = area.cache_key or area.content_hash
    folder = cache_dir() / "thumbnails"
    return folder / f"{stem}-top.png", folder / f"{stem}-perspective.png"


def write_thumbnails(area: Area) -> tuple[Path, Path]:
    """Render both thumbnails of ``area`` into the cache; returns their paths."""
    top, perspective = thumbnail_paths(area)
    write_png(top, render_top(area))
    write_png(perspective, render_perspective(area))
    return top, perspective
