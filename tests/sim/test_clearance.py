"""Traversable clearance between voxel boxes: the tracker and the plan check against brute-force
references on random maps, the clearance the rule guarantees, and the door widths it implies."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import pytest
from scipy.spatial import cKDTree

from sim.clearance import TraversabilityTracker, _clearance_box, guaranteed_clearance_m
from sim.config import EpisodeConfig
from sim.occupancy import OccupancyMap, VoxelState
from sim.search_checks import plan_is_clear, segment_cube_sq, starts_traversable

BoolGrid = npt.NDArray[np.bool_]
IndexArray = npt.NDArray[np.int64]


def obstacle_voxels(state: npt.NDArray[np.uint8]) -> IndexArray:
    """(K, 3) indices of every non-FREE voxel and of the one-voxel shell around the grid (the
    outside of the grid is an obstacle; its nearest points lie on the shell's cubes)."""
    shell = np.argwhere(np.pad(np.zeros(state.shape, dtype=bool), 1, constant_values=True)) - 1
    return np.concatenate([np.argwhere(state != VoxelState.FREE), shell])


def centre_to_cubes(centres: IndexArray, cubes: IndexArray,
                    reach: float) -> npt.NDArray[np.float64]:
    """(N,) distance, in voxels, from each voxel centre to the nearest of the cubes when that is
    below `reach` (else inf): every cube whose centre lies within `reach` plus half a diagonal
    (a KD-tree finds them) is measured, per axis the gap from the centre to its interval."""
    c = centres + 0.5
    near = cKDTree(cubes + 0.5).query_ball_point(c, reach + 0.5 * math.sqrt(3.0) + 1e-9)
    lengths = np.array([len(n) for n in near])
    out = np.full(len(c), np.inf)
    if lengths.sum() == 0:
        return out
    which = np.repeat(np.arange(len(c)), lengths)
    cube = cubes[np.concatenate([np.asarray(n, dtype=np.int64) for n in near if n])]
    gap = np.maximum(np.maximum(cube - c[which], c[which] - (cube + 1)), 0.0)
    np.minimum.at(out, which, np.sqrt((gap**2).sum(axis=1)))
    return np.where(out < reach, out, np.inf)


def reference_traversable(state: npt.NDArray[np.uint8], voxel_size: float,
                          radius_m: float) -> BoolGrid:
    """FREE voxels whose centre is at least the radius from every obstacle cube."""
    free = np.argwhere(state == VoxelState.FREE)
    result = np.zeros(state.shape, dtype=bool)
    if len(free) == 0:
        return result
    radius = radius_m / voxel_size
    dist = centre_to_cubes(free, obstacle_voxels(state), radius)
    ok = free[dist >= radius - 1e-9]
    result[tuple(ok.T)] = True
    return result


def random_state(rng: np.random.Generator, shape: tuple[int, int, int],
                 obstacles: float = 0.02) -> npt.NDArray[np.uint8]:
    state = np.full(shape, VoxelState.FREE, dtype=np.uint8)
    roll = rng.random(shape)
    state[roll < obstacles] = VoxelState.OCCUPIED
    state[roll > 1.0 - obstacles / 2] = VoxelState.UNKNOWN
    return state


def map_with(state: npt.NDArray[np.uint8], voxel_size: float) -> OccupancyMap:
    """An occupancy map holding exactly `state` (written through the private grid: the tracker
    only reads states)."""
    m = OccupancyMap(np.zeros(3), state.shape, voxel_size)
    m._state[...] = state  # a fixture: the tracker reads only the states
    return m


@pytest.mark.parametrize(("voxel_size", "radius_m"),
                         [(0.1, 0.45), (0.2, 0.45), (0.1, 0.3), (0.1, 0.25), (0.2, 0.1),
                          (0.1, 0.07), (0.1, 0.0)])
@pytest.mark.parametrize("seed", range(3))
def test_matches_a_brute_force_reference_on_random_maps(voxel_size: float, radius_m: float,
                                                        seed: int) -> None:
    rng = np.random.default_rng(seed)
    density = (0.0005, 0.004, 0.02)[seed]
    state = random_state(rng, (28, 24, 16), obstacles=density)
    tracker = TraversabilityTracker(map_with(state, voxel_size), radius_m)
    expected = reference_traversable(state, voxel_size, radius_m)
    np.testing.assert_array_equal(tracker.traversable, expected)
    if seed == 0:
        assert expected.any()


@pytest.mark.parametrize("radius_m", [0.25, 0.45])
def test_incremental_updates_match_the_reference(radius_m: float) -> None:
    rng = np.random.default_rng(7)
    m = OccupancyMap((0.3, -0.2, 0.0), (40, 34, 14), 0.1)
    tracker = TraversabilityTracker(m, radius_m)
    size = np.array(m.shape) * m.voxel_size
    for step in range(24):
        origin = m.origin + rng.uniform(0.0, size)
        direction = rng.normal(size=(800, 3))
        direction /= np.linalg.norm(direction, axis=1, keepdims=True)
        ends = origin + direction * rng.uniform(0.05, 3.5, size=(800, 1))
        m.integrate(origin, ends, rng.random(800) < 0.01)
        tracker.update()
        np.testing.assert_array_equal(tracker.traversable,
                                      TraversabilityTracker(m, radius_m).traversable)
        if step % 6 == 5:
            np.testing.assert_array_equal(
                tracker.traversable, reference_traversable(m.state, m.voxel_size, radius_m))
    assert tracker.traversable.any()


@pytest.mark.parametrize(("voxel_size", "margin"), [(0.1, 4), (0.2, 2)])
def test_any_box_is_written_as_the_reference_and_nothing_outside_it(voxel_size: float,
                                                                     margin: int) -> None:
    """The kernel on boxes anywhere in the grid, touching its faces or not, and on every depth
    of z: inside the box the reference, outside it untouched."""
    rng = np.random.default_rng(11)
    state = random_state(rng, (30, 26, 21), obstacles=0.01)
    expected = reference_traversable(state, voxel_size, 0.45)
    tracker = TraversabilityTracker(map_with(state, voxel_size), 0.45)
    assert tracker._margin == margin
    for _ in range(40):
        lo = rng.integers(0, state.shape)
        hi = lo + 1 + rng.integers(0, np.array(state.shape) - lo)
        out = np.zeros(state.shape, dtype=bool)
        _clearance_box(state, out, int(lo[0]), int(lo[1]), int(lo[2]), int(hi[0]), int(hi[1]),
                       int(hi[2]), tracker._margin, tracker._min_sq4)
        inside = (slice(lo[0], hi[0]), slice(lo[1], hi[1]), slice(lo[2], hi[2]))
        np.testing.assert_array_equal(out[inside], expected[inside])
        out[inside] = False
        assert not out.any()


def test_a_centre_exactly_the_radius_from_a_cube_is_traversable() -> None:
    """An obstacle cube 4.5 voxels (0.45 m) from a centre along an axis lets it through; one
    diagonal neighbour of the centre rule's (2, 1, 1) offset at 0.2 m voxels does not."""
    state = np.full((21, 21, 21), VoxelState.FREE, dtype=np.uint8)
    state[15, 10, 10] = VoxelState.OCCUPIED  # its cube starts 4.5 voxels from centre (10, ...)
    trav = TraversabilityTracker(map_with(state, 0.1), 0.45).traversable
    assert trav[10, 10, 10] and not trav[11, 10, 10]
    # With 0.2 m voxels the centre rule passed an obstacle at offset (2, 1, 1): its centre is
    # 0.49 m away but its cube 0.33 m; from anywhere in the traversable cube, 0.2 m.
    state = np.full((21, 21, 21), VoxelState.FREE, dtype=np.uint8)
    state[12, 11, 11] = VoxelState.OCCUPIED
    trav = TraversabilityTracker(map_with(state, 0.2), 0.45).traversable
    assert not trav[10, 10, 10]
    assert trav[8, 8, 8]  # offset (4, 3, 3): its cube is far enough


def least_cube_gap(a: IndexArray, b: IndexArray) -> float:
    """The least distance, in voxels, between a cube of voxels a (N, 3) and one of b (M, 3)."""
    least = np.inf
    for chunk in np.array_split(a, max(1, len(a) // 200)):
        gap = np.maximum(np.abs(chunk[:, None] - b[None]) - 1, 0)
        least = min(least, float(np.sqrt((gap**2).sum(axis=2).min())))
    return least


@pytest.mark.parametrize(("voxel_size", "radius_m"), [(0.1, 0.45), (0.2, 0.45), (0.1, 0.3),
                                                      (0.15, 0.45)])
def test_the_guaranteed_clearance_is_the_least_cube_to_cube_gap(voxel_size: float,
                                                                radius_m: float) -> None:
    """Brute force over every pair of a traversable and an obstacle voxel on random maps: no
    pair comes closer than `guaranteed_clearance_m`, and some map attains it."""
    g = guaranteed_clearance_m(radius_m, voxel_size)
    assert g >= radius_m - 0.5 * math.sqrt(3.0) * voxel_size - 1e-12
    rng = np.random.default_rng(3)
    least = np.inf
    for _ in range(12):
        state = random_state(rng, (18, 18, 18), obstacles=0.01)
        trav = np.argwhere(TraversabilityTracker(map_with(state, voxel_size), radius_m)
                           .traversable)
        if len(trav):
            least = min(least, least_cube_gap(trav, obstacle_voxels(state)))
    assert least * voxel_size >= g - 1e-12
    # A single obstacle: the nearest traversable cube is exactly the guarantee away.
    state = np.full((25, 25, 25), VoxelState.FREE, dtype=np.uint8)
    state[12, 12, 12] = VoxelState.OCCUPIED
    trav = np.argwhere(TraversabilityTracker(map_with(state, voxel_size), radius_m).traversable)
    assert least_cube_gap(trav, np.array([[12, 12, 12]])) * voxel_size == pytest.approx(g)


def test_the_benchmark_vehicle_keeps_clear_on_accepted_paths() -> None:
    """With the benchmark's safety radius (vehicle radius plus margin), a path the plan check
    accepts keeps the vehicle radius from every obstacle cube at the areas' voxel sizes."""
    cfg = EpisodeConfig()
    for voxel_size in (0.1, 0.2):
        worst = guaranteed_clearance_m(cfg.safety_radius_m, voxel_size) - voxel_size / 8.0
        assert worst >= cfg.limits.radius_m, voxel_size
    assert guaranteed_clearance_m(cfg.safety_radius_m, 0.1) == pytest.approx(0.1 * math.sqrt(14))
    assert guaranteed_clearance_m(cfg.safety_radius_m, 0.2) == pytest.approx(0.2 * math.sqrt(3))


@pytest.mark.parametrize("voxel_size", [0.1, 0.2])
def test_accepted_segments_keep_the_guaranteed_clearance(voxel_size: float) -> None:
    """Random segments between traversable voxels on random maps: every one `plan_is_clear`
    accepts stays at least the guarantee less an eighth of a voxel from every obstacle cube
    (exact segment-to-cube distances), and a segment through an obstacle cube is refused."""
    radius_m = EpisodeConfig().safety_radius_m
    bound = guaranteed_clearance_m(radius_m, voxel_size) / voxel_size - 0.125
    rng = np.random.default_rng(5)
    accepted = refused = 0
    for _ in range(6):
        state = random_state(rng, (30, 30, 16), obstacles=0.004)
        trav = TraversabilityTracker(map_with(state, voxel_size), radius_m).traversable
        cells = np.argwhere(trav)
        obstacles = obstacle_voxels(state)
        origin = np.zeros(3)
        for _ in range(40):
            a, b = cells[rng.integers(len(cells), size=2)] + rng.uniform(0.0, 1.0, (2, 3))
            clear = plan_is_clear(trav, state == VoxelState.FREE, origin, voxel_size,
                                  a * voxel_size, (b * voxel_size)[None]) == 1
            # Only obstacles near the segment's box can be nearest.
            near = obstacles[np.all((obstacles >= np.minimum(a, b) - 8)
                                    & (obstacles <= np.maximum(a, b) + 8), axis=1)]
            gaps = [segment_cube_sq(a, b, int(i), int(j), int(k)) for i, j, k in near]
            least = math.sqrt(min(gaps)) if gaps else np.inf
            if clear:
                accepted += 1
                assert least >= bound - 1e-9
            else:
                refused += 1
            if least == 0.0:
                assert not clear
    assert accepted > 20 and refused > 20


def test_segment_to_cube_distance_matches_dense_sampling() -> None:
    rng = np.random.default_rng(9)
    for _ in range(400):
        a, b = rng.uniform(-3.0, 4.0, (2, 3))
        if rng.random() < 0.2:
            b = a.copy()  # a point
        cube = rng.integers(-1, 3, 3)
        t = np.linspace(0.0, 1.0, 20001)[:, None]
        points = a + t * (b - a)
        gap = np.maximum(np.maximum(cube - points, points - (cube + 1)), 0.0)
        sampled = float((gap**2).sum(axis=1).min())
        exact = segment_cube_sq(a, b, int(cube[0]), int(cube[1]), int(cube[2]))
        # The exact minimum is below every sample and within a sample spacing of the best.
        assert exact <= sampled + 1e-12
        step = float(np.linalg.norm(b - a)) / 20000
        assert math.sqrt(sampled) - math.sqrt(exact) <= step + 1e-9


def door_free_voxels(width_m: float, voxel_size: float) -> int:
    """Free voxels across a door whose jambs lie on planes through voxel centres (as in
    `tests/sim/thin_scenes.py`): its width less one voxel."""
    return round(width_m / voxel_size) - 1


def free_run_needed(radius_m: float, voxel_size: float) -> int:
    """The fewest free voxels across an opening that leave a traversable centre: the centre of
    the m-th free voxel is m + 1/2 voxels from the cube of one jamb, so m >= radius - 1/2 on
    both sides."""
    m = math.ceil(radius_m / voxel_size - 0.5 - 1e-9)
    return 2 * m + 1


@pytest.mark.parametrize(("voxel_size", "width_m", "passes"),
                         [(0.1, 0.8, False), (0.1, 0.9, False), (0.1, 1.0, True),
                          (0.2, 1.0, False), (0.2, 1.2, True)])
def test_doors_pass_as_the_rule_implies(voxel_size: float, width_m: float,
                                       passes: bool) -> None:
    """A wall with a door, built voxel by voxel: with the benchmark's 0.45 m safety radius a
    door needs 9 free voxels across at 0.1 m (so 1.0 m, jambs on voxel-centre planes, passes
    with its centre exactly 0.45 m from both jambs' cubes, and 0.8 m does not), 5 at 0.2 m (so
    1.0 m does not pass there, 1.2 m does)."""
    radius_m = EpisodeConfig().safety_radius_m
    n_free = door_free_voxels(width_m, voxel_size)
    assert (n_free >= free_run_needed(radius_m, voxel_size)) == passes
    nx = n_free + 2 * 8
    state = np.full((nx, 30, 30), VoxelState.FREE, dtype=np.uint8)
    state[:, 14:16, :] = VoxelState.OCCUPIED  # the wall, two voxels thick
    state[8:8 + n_free, 14:16, 5:25] = VoxelState.FREE  # the opening, 20 voxels high
    trav = TraversabilityTracker(map_with(state, voxel_size), radius_m).traversable
    through = trav[:, 14:16, 15].all(axis=1)
    assert through.any() == passes
    if passes:
        # Exactly one column when the free run is the least the rule needs.
        assert int(through.sum()) == n_free - free_run_needed(radius_m, voxel_size) + 1


def test_the_free_mask_is_read_only_when_the_start_is_not_traversable() -> None:
    """Where `starts_traversable` holds, `plan_is_clear` gives the same answer with any mask in
    place of the free one (the plan checker passes the traversable mask then); from starts that
    are not traversable, some legs escape through free voxels only the free mask allows."""
    rng = np.random.default_rng(11)
    radius_m = EpisodeConfig().safety_radius_m
    voxel_size = 0.1
    origin = np.array([-0.7, 0.3, -0.2])
    seen = {True: 0, False: 0}
    escaped = 0
    for _ in range(4):
        state = random_state(rng, (30, 30, 16), obstacles=0.0006)
        trav = TraversabilityTracker(map_with(state, voxel_size), radius_m).traversable
        free = state == VoxelState.FREE
        for _ in range(200):
            start = origin + rng.uniform(0.2, 0.8, 3) * np.array(state.shape) * voxel_size
            # Short legs, so that many are clear.
            points = start + np.cumsum(rng.uniform(-0.4, 0.4, (3, 3)), axis=0)
            inside = starts_traversable(trav, origin, voxel_size, start)
            voxel = np.floor((start - origin) / voxel_size).astype(int)
            assert inside == bool(trav[tuple(voxel)])
            seen[inside] += 1
            clear = plan_is_clear(trav, free, origin, voxel_size, start, points)
            if inside:
                assert plan_is_clear(trav, trav, origin, voxel_size, start, points) == clear
                assert plan_is_clear(trav, np.ones_like(free), origin, voxel_size, start,
                                     points) == clear
            else:
                escaped += clear > plan_is_clear(trav, trav, origin, voxel_size, start, points)
    assert min(seen.values()) > 50
    assert escaped > 0
    assert not starts_traversable(trav, origin, voxel_size, origin - 1.0)
