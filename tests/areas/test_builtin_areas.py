"""The eleven built-in areas against the issue's table: geometry, levels, start, ground truth.

Ground truth comes from the disk cache (``$FLYBO_CACHE_DIR``, else ``~/.cache/flybo``), the same
one `flybo areas build all` fills: the first run builds every area once (about two minutes on two
cores), later runs read it back.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import open3d as o3d
import pytest
import trimesh

from areas import Area, area_names, load_area, load_ground_truth
from areas.ground_truth import DEFAULT_SAMPLE_SPACING
from areas.registry import generate_area
from areas.stats import (
    FACE_ORDERS,
    TABLE1,
    face_order,
    flyable_voxels,
    level_heights,
    measure,
    mesh_extent,
)

NAMES = sorted(TABLE1)
VOXEL = {"warehouse": 0.2, "platform-b": 0.2, "powerplant": 0.2}
PLATEAU = {"maze": 700, "offices-a": 600, "offices-b": 750, "offices-c": 1650, "facility-a": 700,
           "facility-b": 750, "facility-c": 1650, "warehouse": 900, "platform-a": 550,
           "platform-b": 1200, "powerplant": 1800}
OUTDOOR = {"platform-a", "platform-b", "powerplant"}


def _distance_scene(area: Area) -> o3d.t.geometry.RaycastingScene:
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor.from_numpy(area.vertices.astype(np.float32)),
        o3d.core.Tensor.from_numpy(area.triangles.astype(np.uint32)),
    )
    return scene


def _distance(area: Area, points: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
    query = o3d.core.Tensor.from_numpy(np.ascontiguousarray(points, dtype=np.float32))
    return _distance_scene(area).compute_distance(query).numpy()


def _exact_distance(area: Area, points: npt.NDArray[np.float32]) -> npt.NDArray[np.float64]:
    """(N,) distance from points to the mesh. Open3D's distance query is off by millimetres on
    long sliver triangles (pipe sides), so points it puts 1 mm or more away are measured exactly
    against every triangle whose box (grown by 1 mm) holds them."""
    distance = _distance(area, points).astype(np.float64)
    corners = area.vertices[area.triangles]
    lo, hi = corners.min(axis=1) - 1e-3, corners.max(axis=1) + 1e-3
    for k in np.flatnonzero(distance >= 1e-3):
        p = points[k].astype(np.float64)
        candidates = corners[np.all((lo <= p) & (p <= hi), axis=1)]
        if len(candidates):
            closest = trimesh.triangles.closest_point(candidates, np.tile(p, (len(candidates), 1)))
            distance[k] = min(distance[k], float(np.linalg.norm(closest - p, axis=1).min()))
    return distance


def test_all_eleven_are_registered() -> None:
    assert area_names() == NAMES


@pytest.mark.parametrize("name", NAMES)
def test_metadata_matches_the_table(name: str) -> None:
    area = load_area(name)
    paper = TABLE1[name]
    assert area.name == name
    assert area.info.levels == paper.levels
    assert area.info.rooms == paper.rooms
    assert area.info.indoor == (name not in OUTDOOR)
    assert area.plateau_s == PLATEAU[name]
    assert area.voxel_size == VOXEL.get(name, 0.1)
    assert area.triangles.dtype == np.int32
    assert face_order(len(area.triangles)) in FACE_ORDERS[name]
    assert len(area.triangles) <= 1_000_000  # the simulator's pybullet and Open3D budget
    # Bounding volume within 10 % of the table on every axis, and the grid covers it.
    for measured, table in zip(mesh_extent(area), paper.bounding, strict=True):
        assert measured == pytest.approx(table, rel=0.1)
    np.testing.assert_allclose(area.extent, paper.bounding, rtol=0.1)


@pytest.mark.parametrize("name", NAMES)
def test_every_component_is_closed_and_consistently_wound(name: str) -> None:
    # Each directed edge occurs once and its reverse occurs too: every component is a closed,
    # consistently oriented surface (components do not share vertices).
    area = load_area(name)
    tri = area.triangles.astype(np.int64)
    n = int(tri.max()) + 1
    a = tri[:, [0, 1, 2]].ravel()
    b = tri[:, [1, 2, 0]].ravel()
    code = np.sort(a * n + b)
    assert not np.any(code[1:] == code[:-1]), "an edge is used twice in the same direction"
    assert np.isin(b * n + a, code).all(), "an edge has no opposite half-edge (a hole)"
    corners = area.vertices[tri]
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    assert np.linalg.norm(cross, axis=1).min() > 0.0, "degenerate triangle"


@pytest.mark.parametrize("name", NAMES)
def test_start_pose_has_clearance(name: str) -> None:
    area = load_area(name)
    start = area.start.position
    assert np.all(start > area.bounds_min) and np.all(start < area.bounds_max)
    assert float(_distance(area, start[None, :].astype(np.float32))[0]) >= 0.5
    # The start floats above a floor, not inside a closed part: a ray down hits within 2.5 m.
    ray = np.concatenate([start, [0.0, 0.0, -1.0]])[None, :].astype(np.float32)
    t = _distance_scene(area).cast_rays(o3d.core.Tensor.from_numpy(ray))["t_hit"].numpy()[0]
    assert t < 2.5


@pytest.mark.parametrize("name", NAMES)
def test_ground_truth_reaches_every_level(name: str) -> None:
    area = load_area(name)
    truth = load_ground_truth(area)
    assert DEFAULT_SAMPLE_SPACING <= 0.02
    assert truth.observable.shape == area.grid_shape
    assert truth.observable_volume_m3 > 0.0
    # Observable space stays inside the area: at most the bounding box.
    assert truth.observable_volume_m3 <= float(np.prod(area.extent)) + 1e-6
    stats = measure(area, truth)
    assert stats.levels == TABLE1[name].levels, stats.level_heights
    # The surface cloud lies on the mesh (stored with at most 0.5 mm rounding).
    pts = truth.surface_points
    assert pts.dtype == np.float32
    assert len(pts) > 1000
    rng = np.random.default_rng(0)
    sample = pts[rng.choice(len(pts), size=min(5000, len(pts)), replace=False)]
    assert float(_exact_distance(area, sample).max()) < 1e-3
    assert np.all(sample >= area.bounds_min - 1e-3) and np.all(sample <= area.bounds_max + 1e-3)


@pytest.mark.parametrize("name", NAMES)
def test_every_level_is_reachable_by_the_vehicle(name: str) -> None:
    # Flood fill of the voxels a 0.3 m sphere can occupy, from the start: it must find a floor
    # with headroom on every level, so every level is reachable in flight.
    area = load_area(name)
    heights = level_heights(area, flyable_voxels(area))
    assert len(heights) == TABLE1[name].levels, heights


@pytest.mark.parametrize("name", NAMES)
def test_generation_is_deterministic_per_seed(name: str) -> None:
    a, b, c = generate_area(name, 3), generate_area(name, 3), generate_area(name, 4)
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.triangles, b.triangles)
    np.testing.assert_array_equal(a.start.position, b.start.position)
    assert a.content_hash == b.content_hash
    assert a.content_hash != c.content_hash
    assert a.cache_key is not None
    assert a.cache_key.startswith(f"{name}-g")
    assert a.cache_key.endswith("-s3")
    assert load_area(name).cache_key == a.cache_key[:-1] + "0"
