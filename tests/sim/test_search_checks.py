"""The in-flight check: obstacles found since a plan was accepted, near the rest of its path
(measured to the obstacle voxels' cubes, as the traversable mask is)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pytest
from scipy.optimize import minimize_scalar

from sim.occupancy import VoxelState
from sim.search_checks import path_meets_new_obstacle, segment_cube_sq

VOXEL = 0.1
ORIGIN = np.array([-1.0, -2.0, 0.0])
SHAPE = (30, 24, 12)


def _segment_cube_distance(a: npt.NDArray[np.float64], b: npt.NDArray[np.float64],
                           lo: npt.NDArray[np.float64], size: float) -> float:
    """Distance between the segment a→b and the cube [lo, lo + size]^3, by minimising the
    (convex) point-to-cube distance along the segment."""
    def dist(t: float) -> float:
        p = a + t * (b - a)
        return float(np.linalg.norm(np.maximum(np.maximum(lo - p, p - (lo + size)), 0.0)))
    best = minimize_scalar(dist, bounds=(0.0, 1.0), method="bounded",
                           options={"xatol": 1e-12})
    return min(float(best.fun), dist(0.0), dist(1.0))


def _reference(state: npt.NDArray[np.uint8], before: npt.NDArray[np.uint8],
               points: npt.NDArray[np.float64], reach_m: float) -> bool | None:
    """Whether a newly occupied voxel's cube lies nearer than `reach_m` to the polyline; None
    when one lies within a micrometre of the reach (too close to call)."""
    new = np.argwhere((state == VoxelState.OCCUPIED) & (before != VoxelState.OCCUPIED))
    corners = ORIGIN + new * VOXEL
    found = False
    for a, b in zip(np.vstack([points[:1], points[:-1]]), points, strict=True):
        for lo in corners:
            d = _segment_cube_distance(a, b, lo, VOXEL)
            if abs(d - reach_m) < 1e-6:
                return None
            found |= d < reach_m
    return found


@pytest.mark.parametrize("seed", range(40))
def test_matches_a_brute_force_reference(seed: int) -> None:
    rng = np.random.default_rng(seed)
    before = rng.choice(np.array([0, 1, 2], dtype=np.uint8), size=SHAPE, p=[0.1, 0.85, 0.05])
    state = before.copy()
    free = np.argwhere(before == VoxelState.FREE)
    turned = free[rng.choice(len(free), size=int(rng.integers(0, 60)), replace=False)]
    state[tuple(turned.T)] = VoxelState.OCCUPIED
    # Some occupied voxels turn free: that is no new obstacle.
    occupied = np.argwhere(before == VoxelState.OCCUPIED)
    cleared = occupied[rng.choice(len(occupied), size=5, replace=False)]
    state[tuple(cleared.T)] = VoxelState.FREE
    upper = ORIGIN + np.array(SHAPE) * VOXEL
    points = rng.uniform(ORIGIN - 0.2, upper + 0.2, size=(int(rng.integers(1, 5)), 3))
    reach = float(rng.choice([0.1, 0.25, 0.39]))
    expected = _reference(state, before, points, reach)
    if expected is not None:
        assert path_meets_new_obstacle(state, before, ORIGIN, VOXEL, reach, points) == expected


def test_an_obstacle_on_the_path_is_found_and_one_beside_it_only_within_reach() -> None:
    before = np.full(SHAPE, VoxelState.FREE, dtype=np.uint8)
    path = np.array([[0.05, -1.0, 0.55], [0.05, -0.45, 0.55]])  # voxels (10, 10-15, 5)
    assert not path_meets_new_obstacle(before, before, ORIGIN, VOXEL, 0.45, path)
    on_path = before.copy()
    on_path[10, 12, 5] = VoxelState.OCCUPIED
    assert path_meets_new_obstacle(on_path, before, ORIGIN, VOXEL, 0.45, path)
    # Already in the map the plan was checked against: not new.
    assert not path_meets_new_obstacle(on_path, on_path, ORIGIN, VOXEL, 0.45, path)
    # Reach is measured to the voxel's cube, not its centre.
    beside = before.copy()
    beside[14, 12, 5] = VoxelState.OCCUPIED  # its cube 0.35 m from the path, its centre 0.4 m
    assert path_meets_new_obstacle(beside, before, ORIGIN, VOXEL, 0.36, path)
    assert not path_meets_new_obstacle(beside, before, ORIGIN, VOXEL, 0.34, path)
    # Past the end of the path it does not count.
    ahead = before.copy()
    ahead[10, 21, 5] = VoxelState.OCCUPIED  # its cube 0.55 m beyond the path's end
    assert not path_meets_new_obstacle(ahead, before, ORIGIN, VOXEL, 0.5, path)
    assert path_meets_new_obstacle(ahead, before, ORIGIN, VOXEL, 0.6, path)


def _every_new_voxel(state: npt.NDArray[np.uint8], before: npt.NDArray[np.uint8],
                     points: npt.NDArray[np.float64], reach_m: float) -> bool:
    """The check's answer from every newly occupied voxel of the grid, each measured with the
    kernel's own exact segment-to-cube distance: what the slab-by-slab scan must reproduce."""
    new = np.argwhere((state == VoxelState.OCCUPIED) & (before != VoxelState.OCCUPIED))
    grid = (points - ORIGIN) / VOXEL
    reach_sq = (reach_m / VOXEL) ** 2
    for a, b in zip(np.vstack([grid[:1], grid[:-1]]), grid, strict=True):
        for i, j, k in new:
            if segment_cube_sq(a, b, int(i), int(j), int(k)) < reach_sq:
                return True
    return False


@pytest.mark.parametrize("seed", range(60))
def test_long_diagonal_paths_match_every_voxel_tested(seed: int) -> None:
    # Long legs in every direction across the grid, with the new voxels placed near them, so
    # that many fall just inside or just outside the reach of a leg.
    rng = np.random.default_rng(1000 + seed)
    before = np.full(SHAPE, VoxelState.FREE, dtype=np.uint8)
    upper = ORIGIN + np.array(SHAPE) * VOXEL
    points = rng.uniform(ORIGIN, upper, size=(int(rng.integers(2, 6)), 3))
    if seed % 3 == 0:
        points[:, int(rng.integers(3))] = points[0, 0]  # legs in a plane of constant coordinate
    state = before.copy()
    t = rng.uniform(0.0, 1.0, size=40)
    leg = rng.integers(1, len(points), size=40)
    near = points[leg - 1] + t[:, None] * (points[leg] - points[leg - 1])
    near += rng.normal(0.0, 0.25, size=near.shape)
    voxels = np.clip(((near - ORIGIN) / VOXEL).astype(np.int64), 0, np.array(SHAPE) - 1)
    state[tuple(voxels.T)] = VoxelState.OCCUPIED
    for reach in (0.05, 0.15, 0.3):
        expected = _every_new_voxel(state, before, points, reach)
        assert path_meets_new_obstacle(state, before, ORIGIN, VOXEL, reach, points) == expected
