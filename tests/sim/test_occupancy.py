"""Occupancy grid: ray traversal against a brute-force reference, sensor model, bookkeeping."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pytest
from pydantic import ValidationError

from sim.occupancy import IndexBox, OccupancyConfig, OccupancyMap, VoxelState

IntArray = npt.NDArray[np.int64]

ORIGIN = np.array([-1.23, 0.37, -0.11])
SHAPE = (23, 17, 11)
VOXEL = 0.1


def reference_voxels(
    origin: npt.NDArray[np.float64], endpoint: npt.NDArray[np.float64], m: OccupancyMap,
    step_m: float = 1e-3,
) -> IntArray:
    """(K, 3) in-grid voxels the segment visits, in order, by sampling it.

    Samples every `step_m` along the segment, plus the midpoint between each pair of
    consecutive voxel-face crossings: fixed steps alone miss a voxel whose corner the segment
    clips over less than a step.
    """
    a = (origin - m.origin) / m.voxel_size
    b = (endpoint - m.origin) / m.voxel_size
    d = b - a
    length = float(np.linalg.norm(endpoint - origin))
    ts = [np.linspace(0.0, 1.0, max(2, int(np.ceil(length / step_m)) + 1))]
    for axis in range(3):
        if d[axis] != 0.0:
            lo, hi = sorted((a[axis], b[axis]))
            faces = np.arange(np.ceil(lo), np.floor(hi) + 1)
            ts.append((faces - a[axis]) / d[axis])
    t = np.unique(np.clip(np.concatenate(ts), 0.0, 1.0))
    t = np.unique(np.concatenate([t, 0.5 * (t[1:] + t[:-1])]))
    idx = np.floor(a + t[:, None] * d).astype(np.int64)
    idx = idx[m.in_bounds(idx)]
    if len(idx) == 0:
        return idx.reshape(0, 3)
    keep = np.concatenate([[True], np.any(idx[1:] != idx[:-1], axis=1)])
    return idx[keep]


def random_rays(
    rng: np.random.Generator, m: OccupancyMap, n: int, outside: float = 0.5
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """One origin (3,) and n endpoints (n, 3), anywhere in the grid box grown by `outside` m."""
    size = np.array(m.shape) * m.voxel_size
    lo = m.origin - outside
    hi = m.origin + size + outside
    return rng.uniform(lo, hi), rng.uniform(lo, hi, size=(n, 3))


def state_recount(m: OccupancyMap) -> int:
    return int(np.count_nonzero(m.state != VoxelState.UNKNOWN))


@pytest.fixture
def grid() -> OccupancyMap:
    return OccupancyMap(ORIGIN, SHAPE, VOXEL)


def test_dda_matches_reference_on_random_rays(grid: OccupancyMap) -> None:
    rng = np.random.default_rng(0)
    for _ in range(60):
        origin, ends = random_rays(rng, grid, 50, outside=0.8)
        for end in ends:
            dda = grid.ray_voxels(origin, end)
            ref = reference_voxels(origin, end, grid)
            np.testing.assert_array_equal(dda, ref)


def test_dda_matches_reference_on_axis_aligned_rays(grid: OccupancyMap) -> None:
    rng = np.random.default_rng(1)
    size = np.array(grid.shape) * grid.voxel_size
    for _ in range(300):
        axis = int(rng.integers(3))
        origin = grid.origin + rng.uniform(-0.3, size + 0.3)
        end = origin.copy()
        end[axis] = grid.origin[axis] + rng.uniform(-0.3, size[axis] + 0.3)
        np.testing.assert_array_equal(grid.ray_voxels(origin, end),
                                      reference_voxels(origin, end, grid))


def test_dda_path_is_face_connected_and_monotone(grid: OccupancyMap) -> None:
    rng = np.random.default_rng(2)
    origin, ends = random_rays(rng, grid, 500)
    for end in ends:
        path = grid.ray_voxels(origin, end)
        steps = np.diff(path, axis=0)
        assert np.all(np.abs(steps).sum(axis=1) == 1)
        for axis in range(3):
            assert np.all(steps[:, axis] >= 0) or np.all(steps[:, axis] <= 0)
        end_idx = grid.world_to_index(end)
        if grid.in_bounds(end_idx):
            np.testing.assert_array_equal(path[-1], end_idx)


def test_integrate_updates_exactly_the_traversed_voxels(grid: OccupancyMap) -> None:
    rng = np.random.default_rng(3)
    origin, ends = random_rays(rng, grid, 200)
    for end in ends:
        m = OccupancyMap(ORIGIN, SHAPE, VOXEL)
        m.integrate(origin, end[None], [False])
        known = {tuple(v) for v in np.argwhere(m.state != VoxelState.UNKNOWN)}
        assert known == {tuple(v) for v in grid.ray_voxels(origin, end)}
        assert m.known_count == len(known)


def test_degenerate_rays_give_sane_paths() -> None:
    """Rays along voxel faces, edges and through corners (exact in binary), and zero length."""
    m = OccupancyMap((0.0, 0.0, 0.0), (8, 8, 8), 0.5)
    cases = [
        ((0.0, 0.0, 0.0), (4.0, 4.0, 4.0)),  # grid diagonal, through every corner
        ((1.0, 1.0, 0.25), (3.0, 3.0, 0.25)),  # through voxel edges
        ((0.5, 0.25, 0.25), (3.5, 0.25, 0.25)),  # starts on a face
        ((0.25, 1.0, 1.0), (3.75, 1.0, 1.0)),  # along a voxel edge
        ((-1.0, 2.0, 2.0), (4.0, 2.0, 2.0)),  # along an edge, from outside, ends on the far face
        ((4.0, 4.0, 4.0), (0.0, 0.0, 0.0)),  # starts on the far corner of the grid
        ((-1.0, -1.0, -1.0), (0.0, 0.0, 0.0)),  # ends exactly on the grid corner
        ((-1.0, 0.0, 4.5), (5.0, 0.0, 4.5)),  # outside, in the plane of a face
        ((2.0, 2.0, 2.0), (2.0, 2.0, 2.0)),  # zero length on a corner
        ((1.3, 1.3, 1.3), (1.3, 1.3, 1.3)),  # zero length inside a voxel
        ((9.0, 9.0, 9.0), (9.0, 9.0, 9.0)),  # zero length outside
    ]
    for a, b in cases:
        origin, end = np.array(a), np.array(b)
        path = m.ray_voxels(origin, end)
        assert np.all(m.in_bounds(path))
        if len(path) > 1:
            steps = np.abs(np.diff(path, axis=0)).sum(axis=1)
            assert np.all(steps == 1), (a, b, path)
        end_idx = m.world_to_index(end)
        if m.in_bounds(end_idx):
            np.testing.assert_array_equal(path[-1], end_idx)
        # Every voxel whose interior the segment crosses is on the path.
        t_off = np.linspace(0.01, 0.99, 99)
        inner = m.world_to_index(origin + t_off[:, None] * (end - origin))
        strict = {tuple(v) for v in inner[m.in_bounds(inner)]}
        assert strict <= {tuple(v) for v in path}
        fresh = OccupancyMap((0.0, 0.0, 0.0), (8, 8, 8), 0.5)
        assert fresh.integrate(origin, end[None], [True]) == len(path)


def test_hit_marks_end_voxel_occupied_and_path_free(grid: OccupancyMap) -> None:
    origin = grid.index_to_world([1, 2, 3])
    end = grid.index_to_world([15, 9, 6])
    grid.integrate(origin, end[None], [True])
    path = grid.ray_voxels(origin, end)
    cfg = grid.config
    assert grid.state[tuple(path[-1])] == VoxelState.OCCUPIED
    assert grid.log_odds[tuple(path[-1])] == np.float32(cfg.log_odds_hit)
    for v in path[:-1]:
        assert grid.state[tuple(v)] == VoxelState.FREE
        assert grid.log_odds[tuple(v)] == np.float32(cfg.log_odds_miss)
    assert grid.known_count == len(path)


def test_miss_ray_frees_its_end_voxel(grid: OccupancyMap) -> None:
    origin = grid.index_to_world([1, 2, 3])
    end = grid.index_to_world([15, 9, 6])
    grid.integrate(origin, end[None], [False])
    path = grid.ray_voxels(origin, end)
    assert np.all(grid.state[tuple(path.T)] == VoxelState.FREE)


def test_max_range_rays_ignored_without_clear_max_range() -> None:
    m = OccupancyMap(ORIGIN, SHAPE, VOXEL, OccupancyConfig(clear_max_range=False))
    origin = m.index_to_world([1, 2, 3])
    ends = m.index_to_world([[15, 9, 6], [5, 14, 2]])
    assert m.integrate(origin, ends, [False, True]) == len(m.ray_voxels(origin, ends[1]))
    assert m.state[15, 9, 6] == VoxelState.UNKNOWN
    assert m.state[5, 14, 2] == VoxelState.OCCUPIED


def test_hit_beyond_the_grid_only_frees(grid: OccupancyMap) -> None:
    origin = grid.index_to_world([3, 3, 3])
    end = grid.index_to_world([40, 3, 3])
    grid.integrate(origin, end[None], [True])
    assert np.count_nonzero(grid.state == VoxelState.OCCUPIED) == 0
    assert grid.known_count == SHAPE[0] - 3


def test_log_odds_are_clamped(grid: OccupancyMap) -> None:
    origin = grid.index_to_world([0, 0, 0])
    target = grid.index_to_world([5, 0, 0])
    for _ in range(20):
        grid.integrate(origin, target[None], [True])
    cfg = grid.config
    assert grid.log_odds[5, 0, 0] == np.float32(cfg.clamp_max)
    assert grid.log_odds[2, 0, 0] == np.float32(cfg.clamp_min)
    # From the lower clamp, three hits make a free voxel occupied again.
    far = grid.index_to_world([2, 0, 0])
    for expected in (VoxelState.FREE, VoxelState.FREE, VoxelState.OCCUPIED):
        grid.integrate(origin, far[None], [True])
        assert grid.state[2, 0, 0] == expected


def test_zero_length_ray_updates_only_its_voxel(grid: OccupancyMap) -> None:
    point = grid.index_to_world([4, 5, 6]) + 0.01
    assert grid.integrate(point, point[None], [True]) == 1
    assert grid.state[4, 5, 6] == VoxelState.OCCUPIED
    assert grid.known_count == 1


def test_non_finite_endpoints_are_skipped(grid: OccupancyMap) -> None:
    origin = grid.index_to_world([1, 1, 1])
    ends = np.array([[np.nan, 0.5, 0.5], [np.inf, 0.0, 0.0], grid.index_to_world([6, 1, 1])])
    assert grid.integrate(origin, ends, [True, True, True]) == 6
    assert grid.integrate([np.nan, 0.0, 0.0], ends[2:], [True]) == 0


def test_newly_known_counter_matches_recount(grid: OccupancyMap) -> None:
    rng = np.random.default_rng(4)
    total = 0
    for _ in range(40):
        origin, ends = random_rays(rng, grid, int(rng.integers(1, 300)), outside=1.0)
        before = state_recount(grid)
        newly = grid.integrate(origin, ends, rng.random(len(ends)) < 0.4)
        assert newly == state_recount(grid) - before
        total += newly
    assert grid.known_count == total == state_recount(grid)
    assert grid.explored_volume_m3 == pytest.approx(total * VOXEL**3)
    # State always agrees with the log-odds.
    known = grid.state != VoxelState.UNKNOWN
    occupied = grid.log_odds > grid.config.occupied_threshold
    np.testing.assert_array_equal(grid.state[known] == VoxelState.OCCUPIED, occupied[known])


def test_rays_from_outside_the_grid(grid: OccupancyMap) -> None:
    rng = np.random.default_rng(5)
    origin = grid.origin + np.array([-2.0, 0.5, 0.3])
    size = np.array(SHAPE) * VOXEL
    ends = rng.uniform(grid.origin, grid.origin + size, size=(200, 3))
    newly = grid.integrate(origin, ends, np.ones(200, dtype=bool))
    assert newly == state_recount(grid) > 0
    expected: set[tuple[int, ...]] = set()
    for end in ends:
        expected |= {tuple(v) for v in reference_voxels(origin, end, grid)}
    assert {tuple(v) for v in np.argwhere(grid.state != VoxelState.UNKNOWN)} == expected


def test_ray_missing_the_grid_changes_nothing(grid: OccupancyMap) -> None:
    origin = grid.origin - 1.0
    ends = grid.origin + np.array([[-0.5, 3.0, 0.2], [-0.1, -0.2, -2.0]])
    assert grid.integrate(origin, ends, [True, False]) == 0
    assert grid.last_touched_box is None
    assert state_recount(grid) == 0


def bbox(mask: npt.NDArray[np.bool_]) -> IndexBox | None:
    idx = np.argwhere(mask)
    if len(idx) == 0:
        return None
    lo, hi = idx.min(axis=0), idx.max(axis=0) + 1
    return IndexBox((int(lo[0]), int(lo[1]), int(lo[2])), (int(hi[0]), int(hi[1]), int(hi[2])))


def test_dirty_box_is_the_box_of_state_changes(grid: OccupancyMap) -> None:
    rng = np.random.default_rng(6)
    every = grid.subscribe()
    slow = grid.subscribe()
    slow_before = grid.copy_state()
    for step in range(30):
        before = grid.copy_state()
        log_before = grid.log_odds.copy()
        origin, ends = random_rays(rng, grid, int(rng.integers(1, 40)))
        grid.integrate(origin, ends, rng.random(len(ends)) < 0.5)
        assert every.take() == bbox(grid.state != before)
        assert every.peek() is None
        touched = grid.last_touched_box
        changed_log = bbox(grid.log_odds != log_before)
        if changed_log is not None:
            assert touched is not None and touched.union(changed_log) == touched
        if step % 7 == 6:
            # A subscriber that refreshes less often sees the union of the changes.
            box = slow.take()
            expected = bbox(grid.state != slow_before)
            assert expected is None or (box is not None and box.union(expected) == box)
            slow_before = grid.copy_state()


def test_index_conversions(grid: OccupancyMap) -> None:
    idx = np.array([[0, 0, 0], [22, 16, 10], [5, 7, 9]])
    centres = grid.index_to_world(idx)
    np.testing.assert_allclose(centres[0], ORIGIN + VOXEL / 2)
    np.testing.assert_array_equal(grid.world_to_index(centres), idx)
    below = ORIGIN - np.array([0.0, 0.0, 1e-9])
    np.testing.assert_array_equal(grid.world_to_index(below), [0, 0, -1])
    assert grid.in_bounds(idx).all()
    assert not grid.in_bounds([[23, 0, 0], [0, -1, 0]]).any()
    assert grid.in_bounds(np.array([1, 2, 3]))


def test_read_only_views(grid: OccupancyMap) -> None:
    with pytest.raises(ValueError):
        grid.state[0, 0, 0] = 1
    with pytest.raises(ValueError):
        grid.log_odds[0, 0, 0] = 1.0
    copy = grid.copy_state()
    copy[0, 0, 0] = 2
    assert grid.state[0, 0, 0] == VoxelState.UNKNOWN


def test_config_validation() -> None:
    with pytest.raises(ValidationError):
        OccupancyConfig(occupied_threshold=4.0)
    with pytest.raises(ValidationError):
        OccupancyConfig(log_odds_miss=0.2)
    with pytest.raises(ValidationError):
        OccupancyConfig(unknown_field=1.0)  # type: ignore[call-arg]


def test_hits_win_within_one_batch() -> None:
    """A voxel both hit and passed through by rays of one frame ends occupied, however many
    rays pass through it, and each voxel is updated once per batch."""
    m = OccupancyMap((0.0, 0.0, 0.0), (20, 20, 20), 0.1)
    origin = np.array([0.05, 1.05, 1.05])
    wall_hit = np.array([[1.05, 1.05, 1.05]])  # ends in voxel (10, 10, 10)
    grazing = np.tile([[1.95, 1.05, 1.05]], (50, 1))  # 50 rays through voxel (10, 10, 10)
    ends = np.vstack([grazing, wall_hit])
    hit = np.array([False] * 50 + [True])
    m.integrate(origin, ends, hit)
    assert m.state[10, 10, 10] == VoxelState.OCCUPIED
    assert m.log_odds[10, 10, 10] == pytest.approx(m.config.log_odds_hit)
    # Voxels the rays share got a single miss, not one per ray.
    assert m.log_odds[5, 10, 10] == pytest.approx(m.config.log_odds_miss)
    # A later frame of misses alone can clear it again, one update per frame.
    m.integrate(origin, grazing, np.zeros(50, dtype=bool))
    assert m.log_odds[10, 10, 10] == pytest.approx(
        m.config.log_odds_hit + m.config.log_odds_miss, abs=1e-6
    )
