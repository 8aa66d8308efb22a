"""MAZE geometry: watertight, right size, seeded, connected with loops, a safe start."""

from __future__ import annotations

from collections import deque

import numpy as np
import open3d as o3d
import pytest
import trimesh

from areas.area import Area
from areas.ground_truth import compute_ground_truth
from areas.maze import (
    CELL_SIZE,
    CELLS,
    EXTRA_OPENINGS,
    HEIGHT,
    WALL_THICKNESS,
    build_maze,
    maze_passages,
)


@pytest.fixture(scope="module")
def maze() -> Area:
    return build_maze(seed=0)


def _mesh(area: Area) -> trimesh.Trimesh:
    return trimesh.Trimesh(area.vertices, area.triangles, process=False)


def test_mesh_is_watertight_with_normals_into_free_space(maze: Area) -> None:
    mesh = _mesh(maze)
    assert mesh.is_watertight
    assert mesh.is_winding_consistent
    # Normals point into the free space, so the enclosed volume comes out negative.
    assert mesh.volume < 0.0
    assert 500 <= len(maze.triangles) <= 5000
    # No T-junctions: merging coincident vertices changes nothing, and each edge has 2 faces.
    merged = trimesh.Trimesh(maze.vertices, maze.triangles, process=True)
    assert len(merged.vertices) == len(maze.vertices)
    assert merged.is_watertight


def test_bounds_and_metadata(maze: Area) -> None:
    np.testing.assert_array_equal(maze.bounds_min, [0.0, 0.0, 0.0])
    np.testing.assert_array_equal(maze.bounds_max, [20.0, 20.0, 2.5])
    half = WALL_THICKNESS / 2.0  # the outer walls are half strips
    assert maze.vertices.min(axis=0).tolist() == [half, half, 0.0]
    assert maze.vertices.max(axis=0).tolist() == [20.0 - half, 20.0 - half, 2.5]
    assert maze.grid_shape == (200, 200, 25)
    assert maze.triangles.dtype == np.int32
    assert maze.plateau_s == 700.0
    assert maze.voxel_size == 0.1
    assert maze.info.title == "MAZE"
    assert maze.info.levels == 1
    assert maze.info.indoor


def test_same_seed_same_arrays_other_seed_other_maze() -> None:
    a, b, c = build_maze(3), build_maze(3), build_maze(4)
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.triangles, b.triangles)
    assert a.start.yaw == b.start.yaw
    assert a.content_hash == b.content_hash
    assert a.content_hash != c.content_hash


def test_layout_is_connected_with_loops() -> None:
    for seed in range(5):
        open_x, open_y = maze_passages(np.random.default_rng(seed))
        # A spanning tree of 100 cells has 99 edges; the extra openings close loops.
        assert open_x.sum() + open_y.sum() == CELLS * CELLS - 1 + EXTRA_OPENINGS
        seen = {(0, 0)}
        queue = deque(seen)
        while queue:
            i, j = queue.popleft()
            steps = [
                (i + 1, j, i < CELLS - 1 and open_x[i, j]),
                (i - 1, j, i > 0 and open_x[i - 1, j]),
                (i, j + 1, j < CELLS - 1 and open_y[i, j]),
                (i, j - 1, j > 0 and open_y[i, j - 1]),
            ]
            for a, b, ok in steps:
                if ok and (a, b) not in seen:
                    seen.add((a, b))
                    queue.append((a, b))
        assert len(seen) == CELLS * CELLS


def test_mesh_free_space_has_loops(maze: Area) -> None:
    # The boundary of a handlebody of genus g has Euler number 2 - 2g; loops mean g > 0.
    genus = (2 - _mesh(maze).euler_number) // 2
    assert genus >= 1


def test_every_cell_reachable_through_the_mesh(maze: Area) -> None:
    truth = compute_ground_truth(maze, sample_spacing=0.1)
    centres = (np.arange(CELLS) * CELL_SIZE + CELL_SIZE / 2.0) / maze.voxel_size
    ij = np.floor(centres).astype(int)
    k = int(HEIGHT / 2.0 / maze.voxel_size)
    assert truth.observable[np.ix_(ij, ij, [k])].all()


def test_start_clearance_and_heading(maze: Area) -> None:
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor.from_numpy(maze.vertices.astype(np.float32)),
        o3d.core.Tensor.from_numpy(maze.triangles.astype(np.uint32)),
    )
    query = o3d.core.Tensor.from_numpy(maze.start.position[None, :].astype(np.float32))
    assert float(scene.compute_distance(query).numpy()[0]) >= 0.5
    np.testing.assert_allclose(maze.start.position, [1.0, 1.0, 1.2])
    # Looking along the yaw, the first wall is beyond the neighbouring cell (> 2 m away).
    heading = np.array([np.cos(maze.start.yaw), np.sin(maze.start.yaw), 0.0])
    ray = np.concatenate([maze.start.position, heading])[None, :].astype(np.float32)
    hit = scene.cast_rays(o3d.core.Tensor.from_numpy(ray))["t_hit"].numpy()[0]
    assert hit > CELL_SIZE
