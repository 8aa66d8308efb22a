"""Ground truth of an area: what a perfect exploration can observe.

Works for any triangle mesh, closed or not, with any winding:

1. Surface samples: the mesh surface sampled uniformly, about one point per ``sample_spacing**2``
   of area (2 cm spacing by default), seeded from the area's content hash so the result is
   reproducible; triangles are sampled in chunks to bound memory on the large areas.
2. Blocked voxels: voxels whose centre lies within ``voxel_size / 2`` of the mesh. Any path of
   6-adjacent voxel centres that crosses the surface crosses it on a segment of length
   ``voxel_size`` between two centres, so one of those centres is within ``voxel_size / 2`` of the
   crossing point: the flood fill cannot pass through any surface, even a zero-thickness sheet.
   The ball of radius ``voxel_size / 2`` is inscribed in the voxel, so a blocked voxel always
   touches the surface and free space next to a wall is not eaten away by more than one layer.
3. Reachable and observable free space (`areas.observability`): the voxels the vehicle's centre
   can reach from the start with the planners' clearance rule (the safety radius to every
   blocked voxel's cube), and the free voxels a level camera of the benchmark's range and
   vertical field of view sees from them.
4. Observable voxels: the observable free voxels plus the surface layer a depth camera sees:
   voxels holding surface (blocked, or holding samples) that touch an observable free voxel by a
   face, edge or corner. Face adjacency alone would drop the voxels along concave edges and
   corners of the free space, whose surface a camera does see; the layer still never reaches
   past the blocked shell behind a surface, so the far side of a wall at least one voxel thick
   stays out. Blocked voxels count as holding surface so that the layer does not depend on
   where the random samples fall.
5. Perceivable surface cloud: the samples lying in that surface layer.

A sample on a voxel face belongs to both voxels sharing the face (it is looked up a tiny step to
either side along its triangle normal): on surfaces aligned with the grid, as in MAZE, every
sample then reaches the voxel on the free side, whatever the rounding of its coordinates, and
stays in the perceivable cloud.
"""

from __future__ import annotations

import contextlib
import itertools
import os
import tempfile
import zipfile
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import open3d as o3d
from scipy import ndimage

from areas.area import Area, GroundTruth
from areas.cache import cache_dir
from areas.observability import ViewModel, observability
from areas.surface_cloud import SurfaceCloud
from areas.surface_samples import draw, points_of, side_voxels

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

DEFAULT_SAMPLE_SPACING = 0.02
# Stored in each cache file; bump when the computation changes so stale files are recomputed.
FORMAT_VERSION = 3
# Triangles are sampled in chunks of about this many points, so that the large areas (tens of
# millions of samples at 2 cm) never hold all float64 samples and their normals at once.
SAMPLE_CHUNK_POINTS = 1 << 21
# Margin on the blocking radius, as a fraction of the voxel size: distances come back in float32,
# and a wall lying exactly on voxel faces must block the voxels touching it on both sides.
BLOCK_RADIUS_MARGIN = 1e-3
# Step off the surface, as a fraction of the voxel size, used to find the voxels on either side of
# a sample; far above float64 rounding and far below any geometric detail.
SIDE_STEP = 1e-4
# Voxel centres are tested in blocks of BLOCK^3; blocks far from the mesh are skipped whole.
BLOCK = 4
QUERY_CHUNK = 1 << 21

_memory_cache: dict[str, GroundTruth] = {}


def sample_surface(
    vertices: FloatArray,
    triangles: npt.NDArray[np.integer],
    spacing: float,
    rng: np.random.Generator,
) -> tuple[FloatArray, FloatArray]:
    """Uniform samples of a triangle mesh surface (`areas.surface_samples.draw`).

    Args:
        vertices: (V, 3) metres.
        triangles: (F, 3) vertex indices.
        spacing: about one sample per ``spacing**2`` square metres.
        rng: random generator.

    Returns:
        points: (N, 3) float64 samples.
        normals: (N, 3) float64 unit normals of the sampled triangles (zero for degenerate ones),
            oriented by the triangle winding.
    """
    return points_of(draw(vertices, triangles, spacing, rng))


def _voxel_index(area: Area, points: FloatArray) -> tuple[IntArray, BoolArray]:
    """Flat voxel indices of (N, 3) points and a (N,) mask of those inside the grid."""
    shape = np.array(area.grid_shape)
    ijk = np.floor((points - area.bounds_min) / area.voxel_size).astype(np.int64)
    inside = np.all((ijk >= 0) & (ijk < shape), axis=1)
    flat = np.ravel_multi_index(tuple(np.clip(ijk, 0, shape - 1).T), area.grid_shape)
    return flat, inside


def _distance_scene(area: Area) -> o3d.t.geometry.RaycastingScene:
    """Open3D distance scene of the mesh, in the grid frame (origin at bounds_min).

    Shifting the origin keeps float32 coordinates small and hence precise.
    """
    scene = o3d.t.geometry.RaycastingScene()
    local = (np.asarray(area.vertices, dtype=np.float64) - area.bounds_min).astype(np.float32)
    scene.add_triangles(
        o3d.core.Tensor.from_numpy(local),
        o3d.core.Tensor.from_numpy(np.ascontiguousarray(area.triangles, dtype=np.uint32)),
    )
    return scene


def _distances(scene: o3d.t.geometry.RaycastingScene, points: FloatArray) -> FloatArray:
    """(N,) unsigned distance to the mesh of (N, 3) grid-frame points, in chunks."""
    out = np.empty(len(points), dtype=np.float64)
    for start in range(0, len(points), QUERY_CHUNK):
        chunk = o3d.core.Tensor.from_numpy(points[start : start + QUERY_CHUNK].astype(np.float32))
        out[start : start + QUERY_CHUNK] = scene.compute_distance(chunk).numpy()
    return out


def blocked_voxels(area: Area) -> BoolArray:
    """(nx, ny, nz) bool: voxels whose centre is within ``voxel_size / 2`` of the mesh."""
    shape = np.array(area.grid_shape)
    vs = area.voxel_size
    radius = 0.5 * vs * (1.0 + BLOCK_RADIUS_MARGIN)
    blocked = np.zeros(area.grid_shape, dtype=bool)
    if len(area.triangles) == 0:
        return blocked
    scene = _distance_scene(area)

    # Coarse pass: a block can hold a blocked voxel only if its centre is within the radius plus
    # the distance from the block centre to its farthest voxel centre.
    n_blocks = -(-shape // BLOCK)
    blocks = np.stack(np.meshgrid(*(np.arange(n) for n in n_blocks), indexing="ij"), -1)
    blocks = blocks.reshape(-1, 3)
    block_centres = (blocks * BLOCK + BLOCK / 2.0) * vs
    reach = radius + 0.5 * (BLOCK - 1) * vs * np.sqrt(3.0)
    near = blocks[_distances(scene, block_centres) <= reach]

    # Fine pass on the voxels of the blocks near the mesh.
    offsets = np.stack(np.meshgrid(*([np.arange(BLOCK)] * 3), indexing="ij"), -1).reshape(-1, 3)
    per_batch = max(1, QUERY_CHUNK // len(offsets))
    for start in range(0, len(near), per_batch):
        ijk = (near[start : start + per_batch, None, :] * BLOCK + offsets[None]).reshape(-1, 3)
        ijk = ijk[np.all(ijk < shape, axis=1)]
        hit = ijk[_distances(scene, (ijk + 0.5) * vs) <= radius]
        blocked[tuple(hit.T)] = True
    return blocked


def compute_ground_truth(
    area: Area, *, sample_spacing: float = DEFAULT_SAMPLE_SPACING, view: ViewModel | None = None
) -> GroundTruth:
    """Observable voxels and perceivable surface samples of an area (see the module docstring).

    Args:
        area: the scene; its start position must lie in an unblocked voxel.
        sample_spacing: surface sampling spacing in metres (about one point per spacing**2).
        view: the vehicle and camera; the benchmark's by default.

    Returns:
        The ground truth on the area's occupancy grid.

    Raises:
        ValueError: when the start lies outside the grid or in a voxel touching the mesh.
    """
    vertices = np.asarray(area.vertices, dtype=np.float64)
    triangles = np.asarray(area.triangles, dtype=np.int64)
    blocked = blocked_voxels(area)
    start_flat, start_inside = _voxel_index(area, area.start.position[None, :])
    start = np.unravel_index(int(start_flat[0]), area.grid_shape)
    if not start_inside[0] or blocked[start]:
        raise ValueError(f"start {area.start.position} of area {area.name!r} is not in free space")

    seen = observability(blocked, (int(start[0]), int(start[1]), int(start[2])),
                         area.voxel_size, view)
    cell = area.voxel_size**3
    volumes = {"free_volume_m3": float(np.count_nonzero(seen.free_component)) * cell,
               "reachable_volume_m3": float(np.count_nonzero(seen.reachable)) * cell,
               "observable_free_m3": float(np.count_nonzero(seen.observable_free)) * cell}
    visible = seen.observable_free
    del seen

    # Two passes over the same seeded samples: the first marks the voxels holding surface, the
    # second keeps the samples of the surface layer. Regenerating is cheaper than holding them.
    seed = int(area.content_hash[:16], 16)
    has_surface = np.zeros(blocked.size, dtype=bool)
    for _, side_a, inside_a, side_b, inside_b in _sample_chunks(
        area, vertices, triangles, sample_spacing, seed
    ):
        has_surface[side_a[inside_a]] = True
        has_surface[side_b[inside_b]] = True

    # Edge and corner neighbours count too: the voxels along a concave edge or corner of the free
    # space touch no reachable voxel by a face, yet a camera sees their surface.
    twenty_six = ndimage.generate_binary_structure(3, 3)
    near_visible = ndimage.binary_dilation(visible, structure=twenty_six).ravel()
    layer = (has_surface | blocked.ravel()) & near_visible
    del has_surface, near_visible
    kept: list[npt.NDArray[np.float32]] = []
    for points, side_a, inside_a, side_b, inside_b in _sample_chunks(
        area, vertices, triangles, sample_spacing, seed
    ):
        perceivable = (inside_a & layer[side_a]) | (inside_b & layer[side_b])
        kept.append(points[perceivable])
    observable = visible | layer.reshape(area.grid_shape)
    return GroundTruth(
        observable=observable,
        surface=SurfaceCloud.of(np.concatenate(kept) if kept else np.zeros((0, 3), np.float32)),
        voxel_size=area.voxel_size,
        **volumes,
    )


def _sample_chunks(
    area: Area, vertices: FloatArray, triangles: IntArray, spacing: float, seed: int
) -> Iterator[tuple[npt.NDArray[np.float32], IntArray, BoolArray, IntArray, BoolArray]]:
    """Surface samples inside the bounds, chunk by chunk of triangles, identical on every call.

    Yields:
        points: (n, 3) float32 samples.
        side_a, side_b: (n,) flat voxel indices a tiny step either side of the surface.
        inside_a, inside_b: (n,) bool, whether those voxels lie in the grid.
    """
    corners = vertices[triangles]
    area_per_tri = 0.5 * np.linalg.norm(
        np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1
    )
    del corners
    expected = np.cumsum(area_per_tri) / spacing**2
    # Chunk boundaries every SAMPLE_CHUNK_POINTS expected samples (and at least one triangle).
    cuts = np.searchsorted(expected, np.arange(SAMPLE_CHUNK_POINTS, expected[-1] if len(expected)
                                               else 0.0, SAMPLE_CHUNK_POINTS))
    edges = np.unique(np.concatenate([[0], cuts, [len(triangles)]]))
    eps = 1e-9 * max(1.0, float(np.max(np.abs(area.extent))))
    low, high = area.bounds_min - eps, area.bounds_max + eps
    for index, (lo, hi) in enumerate(itertools.pairwise(edges)):
        rng = np.random.default_rng([seed, index])
        yield side_voxels(draw(vertices, triangles[lo:hi], spacing, rng), low, high,
                          SIDE_STEP * area.voxel_size, area.bounds_min, area.voxel_size,
                          area.grid_shape)


def ground_truth_path(area: Area) -> Path:
    """Disk cache file of an area's ground truth: named by the generator version and seed for
    built-in areas (``area.cache_key``), by the content hash otherwise.

    The file also records the content hash, checked on reading, so a generator changed without
    bumping its version recomputes its ground truth instead of reading a stale one.
    """
    stem = area.cache_key or area.content_hash
    return cache_dir() / "ground_truth" / f"{stem}.npz"


def _write_atomic(path: Path, truth: GroundTruth, content_hash: str) -> None:
    """Write ``truth`` to ``path`` through a temporary file so readers never see a partial file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.stem, suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            arrays: dict[str, Any] = {
                "version": np.int64(FORMAT_VERSION),
                "content_hash": np.array(content_hash),
                "sample_spacing": np.float64(DEFAULT_SAMPLE_SPACING),
                "shape": np.array(truth.observable.shape, dtype=np.int64),
                "observable": np.packbits(truth.observable.ravel()),
                "voxel_size": np.float64(truth.voxel_size),
                "volumes_m3": np.array([truth.free_volume_m3, truth.reachable_volume_m3,
                                        truth.observable_free_m3]),
                **truth.surface.packed().arrays(),
            }
            np.savez(f, **arrays)
        # mkstemp creates the file private to its owner; the cache is readable like any other file.
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def _read(path: Path, area: Area) -> GroundTruth | None:
    """The cached ground truth at ``path``, or None if missing, unreadable or stale."""
    try:
        with np.load(path) as data:
            if (
                int(data["version"]) != FORMAT_VERSION
                or str(data["content_hash"]) != area.content_hash
                or float(data["sample_spacing"]) != DEFAULT_SAMPLE_SPACING
                or tuple(int(n) for n in data["shape"]) != area.grid_shape
                or float(data["voxel_size"]) != area.voxel_size
            ):
                return None
            count = int(np.prod(area.grid_shape))
            bits = np.unpackbits(data["observable"], count=count).astype(bool)
            surface = SurfaceCloud.from_arrays(data)
            free, reachable, observable_free = (float(v) for v in data["volumes_m3"])
    except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile):
        return None
    return GroundTruth(
        observable=bits.reshape(area.grid_shape), surface=surface, voxel_size=area.voxel_size,
        free_volume_m3=free, reachable_volume_m3=reachable, observable_free_m3=observable_free,
    )


def load_ground_truth(area: Area) -> GroundTruth:
    """The ground truth of an area, from memory, the disk cache, or computed and then cached."""
    key = area.content_hash
    truth = _memory_cache.get(key)
    if truth is not None:
        return truth
    path = ground_truth_path(area)
    truth = _read(path, area) if path.exists() else None
    if truth is None:
        truth = compute_ground_truth(area)
        # Keep the stored (rounded) coordinates in memory too: a worker that computed the
        # ground truth and one that read it from the cache then score runs identically.
        truth = replace(truth, surface=truth.surface.packed())
        _write_atomic(path, truth, key)
    _memory_cache[key] = truth
    return truth


def ensure_cached(area: Area) -> tuple[GroundTruth, bool]:
    """The ground truth of an area, making sure its disk cache file exists.

    Returns:
        The ground truth, and whether a valid cache file was there already.
    """
    path = ground_truth_path(area)
    cached = path.exists() and _read(path, area) is not None
    truth = load_ground_truth(area)
    if not path.exists():  # held in memory from before the cache folder changed
        _write_atomic(path, truth, area.content_hash)
    return truth, cached
