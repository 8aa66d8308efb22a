"""Turning a generated mesh into an Area: start pose search and the cache key.

Each area family has a generator version (``GENERATOR_VERSION`` in its module). Together with the
area name and the seed it forms the area's ``cache_key``, which names the ground-truth cache
file; bump the version whenever a change to a generator changes its output.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import open3d as o3d

from areas.area import Area, AreaInfo, StartPose
from areas.primitives import Mesh

FloatArray = npt.NDArray[np.float64]

# The vehicle is a 0.3 m sphere; the issue asks for 0.5 m of clearance at the start, and a little
# more keeps the first camera frames from starting inside the sensor's minimum range.
START_CLEARANCE = 0.6


def clearance(mesh: Mesh, points: npt.ArrayLike) -> FloatArray:
    """(N,) distance in metres from (N, 3) points to the nearest triangle of ``mesh``."""
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor.from_numpy(np.ascontiguousarray(mesh.vertices, dtype=np.float32)),
        o3d.core.Tensor.from_numpy(np.ascontiguousarray(mesh.triangles, dtype=np.uint32)),
    )
    query = np.ascontiguousarray(np.atleast_2d(np.asarray(points, dtype=np.float32)))
    return scene.compute_distance(o3d.core.Tensor.from_numpy(query)).numpy().astype(np.float64)


def pick_start(mesh: Mesh, nominal: npt.ArrayLike, radius: float = 1.5,
               step: float = 0.1) -> FloatArray:
    """The point nearest ``nominal`` (3,) on a ``step`` lattice within ``radius`` (horizontally,
    same height) with at least ``START_CLEARANCE`` to the mesh.

    Raises:
        ValueError: when no lattice point has the clearance (a generator bug).
    """
    centre = np.asarray(nominal, dtype=np.float64)
    n = round(radius / step)
    offsets = np.arange(-n, n + 1) * step
    dx, dy = np.meshgrid(offsets, offsets, indexing="ij")
    cand = np.column_stack([centre[0] + dx.ravel(), centre[1] + dy.ravel(),
                            np.full(dx.size, centre[2])])
    order = np.argsort(dx.ravel() ** 2 + dy.ravel() ** 2, kind="stable")
    cand = cand[order]
    ok = clearance(mesh, cand) >= START_CLEARANCE
    if not ok.any():
        raise ValueError(f"no start with {START_CLEARANCE} m clearance near {centre.tolist()}")
    return cand[int(np.argmax(ok))]


def finish_area(
    *,
    name: str,
    mesh: Mesh,
    bounds_min: npt.ArrayLike,
    bounds_max: npt.ArrayLike,
    start: npt.ArrayLike,
    yaw: float,
    plateau_s: float,
    voxel_size: float,
    info: AreaInfo,
    generator_version: int,
    seed: int,
) -> Area:
    """An Area from a generated mesh, with its start moved to the nearest point with clearance."""
    position = pick_start(mesh, start)
    return Area(
        name=name,
        vertices=np.ascontiguousarray(mesh.vertices, dtype=np.float64),
        triangles=np.ascontiguousarray(mesh.triangles, dtype=np.int32),
        bounds_min=np.asarray(bounds_min, dtype=np.float64),
        bounds_max=np.asarray(bounds_max, dtype=np.float64),
        start=StartPose(position=position, yaw=float(yaw)),
        plateau_s=plateau_s,
        voxel_size=voxel_size,
        info=info,
        cache_key=f"{name}-g{generator_version}-s{seed}",
    )
