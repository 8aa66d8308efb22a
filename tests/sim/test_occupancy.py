"""Occupancy grid: ray traversal against a brute-force reference, sensor model, bookkeeping."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pytest
from pydantic import ValidationError

from sim.noise import DepthNoiseConfig
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
    # A return is believed until a ray contradicts it: from the lower clamp one hit makes the
    # voxel occupied, as a lone hit would from unknown.
    far = grid.index_to_world([2, 0, 0])
    grid.integrate(origin, far[None], [True])
    assert grid.state[2, 0, 0] == VoxelState.OCCUPIED
    assert grid.log_odds[2, 0, 0] == np.float32(cfg.occupied_threshold + cfg.log_odds_hit)


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


# The surface-evidence rule (`sim.occupancy`): a voxel holding returns from two or more frames
# takes a miss only from a ray through where they lie.

FLOOR = np.array([0.0, 0.0, 0.0])
X = np.array([1.0, 0.0, 0.0])
Y = np.array([0.0, 1.0, 0.0])


def line_map(config: OccupancyConfig | None = None) -> OccupancyMap:
    """A 40 x 20 x 20 grid of 0.1 m voxels from the world origin."""
    return OccupancyMap(FLOOR, (40, 20, 20), 0.1, config)


def test_the_mean_of_the_returns_is_kept_one_per_frame() -> None:
    m = line_map()
    origin = np.array([0.05, 1.05, 1.05])
    voxel = np.array([25, 10, 10])
    inside = np.array([[0.2, 0.3, 0.4], [0.6, 0.5, 0.8], [0.7, 0.1, 0.6]])
    points = (voxel + inside) * 0.1
    for n, p in enumerate(points, start=1):
        # A second ray returning in the same voxel in the same frame is not recorded.
        m.integrate(origin, [p, (voxel + 0.5) * 0.1], [True, True])
        mean, count = m.returns(voxel[None])
        assert count[0] == n
        np.testing.assert_allclose(mean[0], points[:n].mean(axis=0), atol=0.1 / 256 * n)
    mean, count = m.returns([[24, 10, 10]])
    assert count[0] == 0 and np.all(np.isnan(mean[0]))
    # The count saturates at the window; from then on the mean follows the latest returns.
    far = (voxel + 0.9) * 0.1
    for _ in range(40):
        m.integrate(origin, [far], [True])
    mean, count = m.returns(voxel[None])
    assert count[0] == 16
    np.testing.assert_allclose(mean[0], far, atol=0.1 * 0.05)


def seen_twice(m: OccupancyMap, point: npt.NDArray[np.float64]) -> None:
    """Two frames of a return at `point` from the -x side, so its voxel holds returns from two
    frames and is occupied."""
    for _ in range(2):
        m.integrate(point - np.array([2.0, 0.0, 0.0]), point[None], [True])


def test_rays_passing_beside_seen_returns_leave_them() -> None:
    """A thin vertical surface at x = 2.52 seen twice from -x: rays from -y passing 3 cm beside
    the returns' mean and on to the far wall do not count as misses; one through the mean does,
    once per frame."""
    m = line_map()
    p = np.array([2.52, 1.03, 1.04])  # in voxel (25, 10, 10)
    seen_twice(m, p)
    idx = (25, 10, 10)
    before = m.log_odds[idx]
    assert before == pytest.approx(2 * m.config.log_odds_hit)
    origin = np.array([p[0] + 0.03, 0.05, p[2]])
    beside = np.array([[p[0] + 0.03, 1.95, p[2]], [p[0] + 0.015, 1.95, p[2] - 0.01]])
    for _ in range(5):
        m.integrate(origin, beside, [True, True])
    assert m.log_odds[idx] == before
    assert m.state[idx] == VoxelState.OCCUPIED
    # Their voxels on the way that held no returns were freed as usual.
    assert m.state[25, 5, 10] == VoxelState.FREE
    through = np.array([p[0], 0.05, p[2]])
    m.integrate(through, [[p[0], 1.95, p[2]], [p[0] + 0.002, 1.95, p[2]]], [True, True])
    assert m.log_odds[idx] == pytest.approx(before + m.config.log_odds_miss)


def test_a_lone_return_is_taken_by_rays_through_it_or_ending_just_behind_it() -> None:
    """Returns from one frame (however many) are believed until a ray contradicts them: one
    through the return (within the radius), or one returning on a surface just behind it, of
    which the return may be depth-noise speckle (within a voxel's diagonal plus the noise
    margin); rays passing beside it and running on leave it alone."""
    m = line_map()
    cfg = m.config
    p = np.array([2.52, 1.03, 1.04])
    m.integrate(p - 2.0 * X, [p, p + 0.001], [True, True])
    idx = (25, 10, 10)
    assert m.state[idx] == VoxelState.OCCUPIED
    beside = np.array([p[0] + 0.04, 0.05, p[2]])
    for _ in range(3):
        m.integrate(beside, [[p[0] + 0.04, 1.95, p[2]]], [True])
        m.integrate(beside, [[p[0] + 0.04, 1.95, p[2]]], [False])
    assert m.log_odds[idx] == np.float32(cfg.log_odds_hit)
    # A wall 12 cm behind the return, seen 4 cm beside it: the return may be its speckle.
    m.integrate(beside, [[p[0] + 0.04, p[1] + 0.12, p[2]]], [True])
    assert m.log_odds[idx] == pytest.approx(cfg.log_odds_hit + cfg.log_odds_miss)
    # A ray through the return and on.
    m.integrate(p - 0.5 * Y, [p + 0.9 * Y], [False])
    assert m.log_odds[idx] == pytest.approx(cfg.log_odds_hit + 2 * cfg.log_odds_miss)
    m.integrate(p - 0.5 * Y, [p + 0.9 * Y], [True])
    assert m.state[idx] == VoxelState.FREE


def test_a_return_in_a_free_voxel_makes_it_occupied() -> None:
    """A 2 cm rod in a 0.2 m voxel: rays passing beside it free the voxel before any hits the
    rod; the first return in it makes it occupied (as a lone hit from unknown would) and rays
    passing beside the rod afterwards leave it so. Summing log-odds, it stayed FREE, and a
    flight that no longer faced the rod flew into it (NBVP on WAREHOUSE, 2026.12-10 before
    this rule)."""
    m = OccupancyMap(FLOOR, (20, 10, 10), 0.2)
    cfg = m.config
    rod = np.array([2.1, 1.1, 1.1])  # in voxel (10, 5, 5)
    idx = (10, 5, 5)
    beside = np.array([rod[0] + 0.06, 0.05, rod[2]])
    for _ in range(4):
        m.integrate(beside, [[rod[0] + 0.06, 1.95, rod[2]]], [True])
    assert m.state[idx] == VoxelState.FREE
    box = m.subscribe()
    m.integrate(rod - 3.0 * X, [rod], [True])
    assert m.state[idx] == VoxelState.OCCUPIED
    assert m.log_odds[idx] == pytest.approx(cfg.occupied_threshold + cfg.log_odds_hit)
    changed = box.take()
    assert changed is not None
    assert all(lo <= i < hi for lo, i, hi in zip(changed.lo, idx, changed.hi, strict=True))
    for _ in range(4):
        m.integrate(beside, [[rod[0] + 0.06, 1.95, rod[2]]], [True])
    assert m.state[idx] == VoxelState.OCCUPIED


@pytest.mark.parametrize("misses", [0, 1, 2, 3, 6])
def test_a_hit_leaves_a_voxel_at_least_as_occupied_as_a_lone_hit(misses: int) -> None:
    """However many misses came before (rays through a voxel without returns), a hit leaves it
    at least at the log-odds of a lone hit, never in between (two misses and a hit summed
    to 0.05, one miss from FREE)."""
    m = line_map()
    cfg = m.config
    p = np.array([2.55, 1.05, 1.05])
    idx = (25, 10, 10)
    for _ in range(misses):
        m.integrate(p - 2.0 * X, [p + 0.5 * X], [True])
    m.integrate(p - 2.0 * X, [p], [True])
    assert m.log_odds[idx] == np.float32(cfg.occupied_threshold + cfg.log_odds_hit)
    assert m.state[idx] == VoxelState.OCCUPIED
    m.integrate(p - 2.0 * X, [p], [True])
    assert m.log_odds[idx] == np.float32(cfg.occupied_threshold + 2 * cfg.log_odds_hit)


def test_returns_within_the_range_noise_beyond_the_mean_agree_with_it() -> None:
    """A ray through the mean that returns just beyond it (range noise of the same surface) is
    no miss; one that runs on well past it is. At 3 m the margin is 1 cm plus twice sigma(3 m),
    about 3.8 cm."""
    m = line_map()
    p = np.array([3.08, 1.05, 1.05])  # near the far face of voxel (30, 10, 10)
    seen_twice(m, p)
    idx = (30, 10, 10)
    before = m.log_odds[idx]
    origin = p - np.array([3.0, 0.0, 0.0])
    m.integrate(origin, [p + 0.03 * X], [True])  # returns in voxel 31, 3 cm beyond
    assert m.log_odds[idx] == before
    m.integrate(origin, [p + 0.06 * X], [True])
    assert m.log_odds[idx] == pytest.approx(before + m.config.log_odds_miss)
    # Without range noise the margin is the radius alone.
    exact = line_map(OccupancyConfig(range_noise=DepthNoiseConfig(enabled=False)))
    seen_twice(exact, p)
    exact.integrate(origin, [p + 0.03 * X], [True])
    assert exact.log_odds[idx] == pytest.approx(before + m.config.log_odds_miss)
    # A ray without a return passing through the mean is a miss wherever it ends.
    m.integrate(origin, [p + 0.001 * X], [False])
    assert m.log_odds[idx] == pytest.approx(before + 2 * m.config.log_odds_miss)


def test_a_voxel_driven_to_the_floor_forgets_its_returns() -> None:
    m = line_map()
    p = np.array([2.55, 1.05, 1.05])
    seen_twice(m, p)
    idx = (25, 10, 10)
    origin = p - np.array([2.0, 0.0, 0.0])
    cfg = m.config
    steps = int(np.ceil((2 * cfg.log_odds_hit - cfg.clamp_min) / -cfg.log_odds_miss))
    for _ in range(steps):
        assert m.returns([idx])[1][0] == 2
        m.integrate(origin, [p + 1.0 * X], [True])  # through the mean
    assert m.log_odds[idx] == np.float32(cfg.clamp_min)
    assert m.returns([idx])[1][0] == 0
    # New returns start a new mean, and the voxel is occupied again.
    m.integrate(origin, [p + 0.03 * X], [True])
    assert m.returns([idx])[1][0] == 1
    assert m.log_odds[idx] == np.float32(cfg.occupied_threshold + cfg.log_odds_hit)
    np.testing.assert_allclose(m.returns([idx])[0][0], p + 0.03 * X, atol=0.1 / 256)


def reference_integrate(ref: dict[str, npt.NDArray[np.float64]], m: OccupancyMap,
                        origin: npt.NDArray[np.float64], ends: npt.NDArray[np.float64],
                        hit: npt.NDArray[np.bool_], tally: list[int]) -> None:
    """The update rule of `sim.occupancy`, voxel by voxel over `reference_voxels` paths:
    `ref` holds "log_odds" (nx, ny, nz), "mean" (nx, ny, nz, 3) in 1/256ths of the voxel and
    "count" (nx, ny, nz). `tally` counts the hits lifted to a lone hit's log-odds, and the misses
    of lone returns by a ray through them and by a ray returning just behind them."""
    cfg, vs = m.config, m.voxel_size
    lo, mean, count = ref["log_odds"], ref["mean"], ref["count"]
    in_grid = [m.in_bounds(m.world_to_index(e)) and h for e, h in zip(ends, hit, strict=True)]
    hit_voxels = {tuple(m.world_to_index(e)) for e, ok in zip(ends, in_grid, strict=True) if ok}
    done: set[tuple[int, ...]] = set()
    recorded: set[tuple[int, ...]] = set()
    a = (origin - m.origin) / vs
    for e, h, ok in zip(ends, hit, in_grid, strict=True):
        b = (e - m.origin) / vs
        d = b - a
        length = float(np.linalg.norm(d))
        sigma = cfg.range_noise.sigma_a + cfg.range_noise.sigma_b * (
            length * vs - cfg.range_noise.z0) ** 2
        margin = (cfg.miss_radius_m + 2.0 * sigma) / vs
        for v in map(tuple, reference_voxels(origin, e, m)):
            if v in done:
                continue
            if v in hit_voxels:
                delta = cfg.log_odds_hit
            else:
                if count[v] >= 1:
                    p = np.array(v) + (mean[v] + 0.5) / 256.0
                    t = float((p - a) @ d) / length**2 if length > 0 else 0.0
                    beyond = (1.0 - t) * length
                    through = True
                    if count[v] >= 2 and h and beyond <= margin:
                        continue
                    if count[v] == 1 and h and beyond <= margin + np.sqrt(3.0):
                        through = False  # a surface just behind a lone return
                    nearest = a + min(max(t, 0.0), 1.0) * d
                    if through and np.linalg.norm(p - nearest) > cfg.miss_radius_m / vs:
                        continue
                    if count[v] == 1:
                        tally[1 if through else 2] += 1
                delta = cfg.log_odds_miss
            done.add(v)
            lo[v] = np.float32(min(max(lo[v] + delta, cfg.clamp_min), cfg.clamp_max))
            lifted = np.float32(min(cfg.occupied_threshold + cfg.log_odds_hit, cfg.clamp_max))
            if delta > 0 and lo[v] < lifted:
                lo[v] = lifted
                tally[0] += 1
            if delta < 0 and lo[v] <= np.float32(cfg.clamp_min):
                count[v] = 0
        if ok:
            v = tuple(m.world_to_index(e))
            if v not in recorded:
                recorded.add(v)
                q = np.minimum(np.floor((b - np.floor(b)) * 256.0), 255.0)
                n = min(count[v] + 1, 16)
                mean[v] = q if n == 1 else mean[v] + np.floor((q - mean[v]) / n + 0.5)
                count[v] = n


def test_the_kernel_matches_a_reference_of_the_rule_on_random_frames() -> None:
    """Random frames whose returns fall on a few 'surface' points, so that voxels collect
    returns over frames; a 4 cm radius so that random rays pass within it."""
    rng = np.random.default_rng(11)
    cfg = OccupancyConfig(miss_radius_m=0.04)
    m = OccupancyMap(ORIGIN, (14, 12, 8), VOXEL, cfg)
    ref = {"log_odds": np.zeros(m.shape), "mean": np.zeros((*m.shape, 3)),
           "count": np.zeros(m.shape, dtype=np.int64)}
    size = np.array(m.shape) * VOXEL
    surface = m.origin + rng.uniform(0.1, size - 0.1, size=(12, 3))
    protected_misses = 0
    tally = [0, 0, 0]
    for _ in range(60):
        origin = m.origin + rng.uniform(-0.3, size + 0.3)
        n = int(rng.integers(5, 60))
        ends = surface[rng.integers(len(surface), size=n)] + rng.normal(0.0, 0.02, (n, 3))
        free_ends = rng.uniform(m.origin - 0.2, m.origin + size + 0.2, size=(n, 3))
        hit = rng.random(n) < 0.6
        ends = np.where(hit[:, None], ends, free_ends)
        before = ref["log_odds"].copy()
        m.integrate(origin, ends, hit)
        reference_integrate(ref, m, origin, ends, hit, tally)
        protected_misses += int(np.count_nonzero((ref["log_odds"] < before) & (ref["count"] >= 2)))
        np.testing.assert_array_equal(m.log_odds, ref["log_odds"].astype(np.float32))
        idx = np.argwhere(np.ones(m.shape, dtype=bool))
        mean, count = m.returns(idx)
        np.testing.assert_array_equal(count, ref["count"].reshape(-1))
        held = count > 0
        expected = m.origin + (idx + (ref["mean"].reshape(-1, 3) + 0.5) / 256.0) * VOXEL
        np.testing.assert_allclose(mean[held], expected[held], atol=1e-9)
        known = m.state != VoxelState.UNKNOWN
        np.testing.assert_array_equal(m.state[known] == VoxelState.OCCUPIED,
                                      m.log_odds[known] > cfg.occupied_threshold)
    # Both branches of the rule were exercised.
    assert protected_misses > 0
    assert min(tally) > 0, tally
    assert np.count_nonzero(ref["count"] >= 2) > 5


def settled_bits(m: OccupancyMap) -> npt.NDArray[np.bool_]:
    """(nx, ny, nz) the map's bits of voxels whose returns word is SETTLED."""
    size = int(np.prod(m.shape))
    return np.unpackbits(m._settled, bitorder="little")[:size].astype(bool).reshape(m.shape)


def test_the_settled_bits_mark_exactly_the_voxels_at_the_floor() -> None:
    """The kernel steps over voxels by their bits: a bit is set exactly where a miss drove the
    voxel to the floor and no hit has come since, including a hit in the batch that follows a
    ray passing through the voxel before the ray that returns in it."""
    rng = np.random.default_rng(5)
    m = OccupancyMap(ORIGIN, (14, 12, 8), VOXEL, OccupancyConfig(miss_radius_m=0.04))
    floor = np.float32(m.config.clamp_min)
    size = np.array(m.shape) * VOXEL
    surface = m.origin + rng.uniform(0.1, size - 0.1, size=(6, 3))
    for _ in range(80):
        origin = m.origin + rng.uniform(-0.3, size + 0.3)
        n = int(rng.integers(5, 60))
        hit = rng.random(n) < 0.3
        ends = np.where(hit[:, None],
                        surface[rng.integers(len(surface), size=n)] + rng.normal(0.0, 0.02, (n, 3)),
                        rng.uniform(m.origin - 0.2, m.origin + size + 0.2, size=(n, 3)))
        m.integrate(origin, ends, hit)
        np.testing.assert_array_equal(settled_bits(m), m.log_odds == floor)
    assert settled_bits(m).any()

    line = line_map()
    p = np.array([2.55, 1.05, 1.05])
    idx = (25, 10, 10)
    origin = p - np.array([2.0, 0.0, 0.0])
    while line.log_odds[idx] > floor:
        line.integrate(origin, [p + 1.0 * X], [False])
    assert settled_bits(line)[idx]
    # The first ray passes through the voxel, the second returns in it: the hit wins.
    line.integrate(origin, [p + 1.0 * X, p + 0.03 * X], [False, True])
    assert not settled_bits(line)[idx]
    assert line.state[idx] == VoxelState.OCCUPIED
    assert line.returns([idx])[1][0] == 1
