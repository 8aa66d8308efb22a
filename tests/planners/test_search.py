"""Path search on the voxel grid: distance fields, paths, corner cutting, shortcuts, and finding
the nearest traversable voxel."""

from __future__ import annotations

import heapq
import itertools
import math

import numpy as np
import numpy.typing as npt
import pytest

from planners.astar import PathCache
from planners.search import (
    DistanceField,
    _grown,
    _heap_pop,
    _heap_push,
    _new_heap,
    segment_clear,
    shortcut,
)
from planners.waypoints import grid_path, nearest_traversable
from sim.occupancy import VoxelState
from tests.planners.conftest import stack_from_state

BoolGrid = npt.NDArray[np.bool_]
VOXEL = 0.1
SQRT2 = math.sqrt(2.0)
SQRT3 = math.sqrt(3.0)


def reference_distances(passable: BoolGrid, start: tuple[int, int, int]) -> npt.NDArray[np.float64]:
    """Plain Dijkstra in voxels, 26-connected; a step is allowed only when every voxel of the
    cube it spans is passable (no corner cutting)."""
    shape = passable.shape
    dist = np.full(shape, np.inf)
    dist[start] = 0.0
    heap = [(0.0, start)]
    offsets = [o for o in itertools.product((-1, 0, 1), repeat=3) if o != (0, 0, 0)]
    while heap:
        d, cur = heapq.heappop(heap)
        if d > dist[cur]:
            continue
        for o in offsets:
            nxt = (cur[0] + o[0], cur[1] + o[1], cur[2] + o[2])
            if not all(0 <= v < n for v, n in zip(nxt, shape, strict=True)):
                continue
            cube = itertools.product(*({c, n} for c, n in zip(cur, nxt, strict=True)))
            if not all(passable[c] for c in cube):
                continue
            nd = d + math.sqrt(sum(v * v for v in o))
            if nd < dist[nxt] - 1e-12:
                dist[nxt] = nd
                heapq.heappush(heap, (nd, nxt))
    return dist


def octile_3d(delta: npt.NDArray[np.int64]) -> npt.NDArray[np.float64]:
    """26-connected distance in voxels on an open grid: diagonal, then face-diagonal, then
    straight steps."""
    a, b, c = np.moveaxis(np.sort(np.abs(delta), axis=-1)[..., ::-1], -1, 0)
    return c * SQRT3 + (b - c) * SQRT2 + (a - b)


def assert_chain(path: npt.NDArray[np.int64], passable: BoolGrid,
                 start: tuple[int, int, int], goal: tuple[int, int, int]) -> None:
    """A connected chain of 26-neighbours through passable voxels, from start to goal."""
    assert path.ndim == 2
    assert path.shape[1] == 3
    assert tuple(path[0]) == start
    assert tuple(path[-1]) == goal
    steps = np.diff(path, axis=0)
    assert np.all(np.abs(steps) <= 1)
    assert np.all(np.any(steps != 0, axis=1))
    assert np.all(passable[path[:, 0], path[:, 1], path[:, 2]])


# -- distances ----------------------------------------------------------------------------------


def _swap_heap_order(pushes: list[tuple[float, int]], pops_between: list[int]) -> list[int]:
    """The reference: a binary heap of two arrays moved by swaps, as the searches' heap was
    before its rows were interleaved. Returns the values in the order they pop."""
    keys: list[float] = []
    vals: list[int] = []
    out: list[int] = []

    def pop() -> None:
        out.append(vals[0])
        keys[0], vals[0] = keys[-1], vals[-1]
        keys.pop()
        vals.pop()
        i, size = 0, len(keys)
        while 2 * i + 1 < size:
            c = 2 * i + 1
            if c + 1 < size and keys[c + 1] < keys[c]:
                c += 1
            if keys[i] <= keys[c]:
                break
            keys[c], keys[i] = keys[i], keys[c]
            vals[c], vals[i] = vals[i], vals[c]
            i = c

    for (key, val), pops in zip(pushes, pops_between, strict=True):
        keys.append(key)
        vals.append(val)
        i = len(keys) - 1
        while i > 0 and keys[(i - 1) >> 1] > keys[i]:
            p = (i - 1) >> 1
            keys[p], keys[i] = keys[i], keys[p]
            vals[p], vals[i] = vals[i], vals[p]
            i = p
        for _ in range(min(pops, len(keys))):
            pop()
    while keys:
        pop()
    return out


@pytest.mark.parametrize("seed", range(3))
def test_the_heap_pops_ties_in_the_swap_heaps_order(seed: int) -> None:
    """Which of equal keys pops first decides between paths of equal length: the interleaved
    heap must pop them as the swap-based heap did, through its growth and interleaved pops."""
    rng = np.random.default_rng(seed)
    n = 5000
    # Few distinct keys, so that most comparisons are ties.
    pushes = [(float(k), int(v)) for k, v in zip(rng.integers(0, 12, n) * 0.5,
                                                  rng.permutation(n), strict=True)]
    pops_between = [int(p) for p in rng.integers(0, 3, n)]
    heap, size, got = _new_heap(4), 0, []
    for (key, val), pops in zip(pushes, pops_between, strict=True):
        heap = _grown(heap, size + 1)
        _heap_push(heap, size, key, val)
        size += 1
        for _ in range(min(pops, size)):
            got.append(int(heap[0, 1]))
            size = _heap_pop(heap, size)
    while size:
        got.append(int(heap[0, 1]))
        size = _heap_pop(heap, size)
    assert got == _swap_heap_order(pushes, pops_between)


def test_distances_on_an_open_grid() -> None:
    passable = np.ones((10, 9, 8), dtype=bool)
    start = (2, 3, 1)
    field = DistanceField(passable, start, VOXEL)
    assert field.dist_m.shape == passable.shape
    assert field.nearest_goal is None
    assert field.dist_m[start] == 0.0
    # Five straight steps, a pure diagonal of three, a face diagonal of two plus one straight.
    assert field.dist_m[7, 3, 1] == pytest.approx(0.5)
    assert field.dist_m[5, 6, 4] == pytest.approx(3 * SQRT3 * VOXEL)
    assert field.dist_m[2, 0, 1] == pytest.approx(0.3)
    assert field.dist_m[4, 5, 1] == pytest.approx(2 * SQRT2 * VOXEL)
    assert field.dist_m[5, 5, 1] == pytest.approx((2 * SQRT2 + 1) * VOXEL)
    # Every voxel against the closed form and an independent Dijkstra.
    idx = np.stack(np.indices(passable.shape), axis=-1)
    expected = octile_3d(idx - np.array(start)) * VOXEL
    np.testing.assert_allclose(field.dist_m, expected, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(field.dist_m, reference_distances(passable, start) * VOXEL,
                               rtol=1e-12, atol=1e-12)


def test_distances_scale_with_the_voxel_size() -> None:
    passable = np.ones((6, 6, 6), dtype=bool)
    coarse = DistanceField(passable, (0, 0, 0), 0.25)
    assert coarse.dist_m[4, 0, 0] == pytest.approx(1.0)
    assert coarse.dist_m[3, 3, 3] == pytest.approx(3 * SQRT3 * 0.25)


def test_blocked_voxels_are_unreachable_and_never_entered() -> None:
    passable = np.ones((5, 5, 5), dtype=bool)
    passable[2, 2, 2] = False
    field = DistanceField(passable, (0, 0, 0), VOXEL)
    assert math.isinf(field.dist_m[2, 2, 2])
    assert field.path_to((2, 2, 2)).shape == (0, 3)
    np.testing.assert_allclose(
        field.dist_m, reference_distances(passable, (0, 0, 0)) * VOXEL, rtol=1e-12
    )


def test_max_cost_stops_the_search() -> None:
    passable = np.ones((20, 3, 3), dtype=bool)
    field = DistanceField(passable, (0, 1, 1), VOXEL, max_cost_m=0.55)
    assert field.dist_m[5, 1, 1] == pytest.approx(0.5)
    assert math.isinf(field.dist_m[15, 1, 1])
    assert field.path_to((15, 1, 1)).shape == (0, 3)


# -- a wall with a gap --------------------------------------------------------------------------


def _wall_with_gap() -> tuple[BoolGrid, tuple[int, int, int]]:
    passable = np.ones((10, 10, 3), dtype=bool)
    passable[5, :, :] = False
    gap = (5, 8, 1)
    passable[gap] = True
    return passable, gap


def test_wall_with_a_gap_forces_the_path_through_the_gap() -> None:
    passable, gap = _wall_with_gap()
    start, goal = (1, 1, 1), (8, 1, 1)
    field = DistanceField(passable, start, VOXEL)
    path = field.path_to(goal)
    assert_chain(path, passable, start, goal)
    assert any(tuple(p) == gap for p in path)
    # The path is as long as the distance field says, and that is the true shortest length.
    steps = np.linalg.norm(np.diff(path, axis=0), axis=1)
    assert float(np.sum(steps)) * VOXEL == pytest.approx(field.dist_m[goal])
    reference = reference_distances(passable, start)
    assert field.dist_m[goal] == pytest.approx(reference[goal] * VOXEL)
    np.testing.assert_allclose(field.dist_m, reference * VOXEL, rtol=1e-12)
    # Far longer than straight through the wall.
    assert field.dist_m[goal] > 1.2


def test_wall_without_a_gap_leaves_the_goal_unreachable() -> None:
    passable, gap = _wall_with_gap()
    passable[gap] = False
    start, goal = (1, 1, 1), (8, 1, 1)
    goals = np.zeros(passable.shape, dtype=bool)
    goals[goal] = True
    field = DistanceField(passable, start, VOXEL, goals=goals)
    assert field.nearest_goal is None
    assert math.isinf(field.dist_m[goal])
    path = field.path_to(goal)
    assert path.shape == (0, 3)
    assert path.dtype == np.int64
    # Everything on the start's side of the wall is reached.
    assert np.all(np.isfinite(field.dist_m[:5]))
    assert np.all(np.isinf(field.dist_m[5:]))


def test_path_to_the_start_is_the_start() -> None:
    passable = np.ones((4, 4, 4), dtype=bool)
    field = DistanceField(passable, (1, 2, 3), VOXEL)
    np.testing.assert_array_equal(field.path_to((1, 2, 3)), [[1, 2, 3]])


# -- goals ---------------------------------------------------------------------------------------


def test_goal_mask_stops_at_the_nearest_goal() -> None:
    passable = np.ones((12, 12, 1), dtype=bool)
    start = (0, 0, 0)
    goals = np.zeros(passable.shape, dtype=bool)
    goals[3, 0, 0] = True  # 3 straight steps: 0.3 m
    goals[2, 2, 0] = True  # 2 diagonal steps: 0.283 m, nearer although listed later in x
    goals[9, 9, 0] = True
    field = DistanceField(passable, start, VOXEL, goals=goals)
    assert field.nearest_goal is not None
    assert field.nearest_goal.dtype == np.int64
    np.testing.assert_array_equal(field.nearest_goal, [2, 2, 0])
    assert field.dist_m[2, 2, 0] == pytest.approx(2 * SQRT2 * VOXEL)
    # The search stopped there: the far goal was never reached.
    assert math.isinf(field.dist_m[9, 9, 0])
    path = field.path_to(field.nearest_goal)
    assert_chain(path, passable, start, (2, 2, 0))
    assert len(path) == 3


def test_goal_at_the_start_is_found_immediately() -> None:
    passable = np.ones((5, 5, 5), dtype=bool)
    goals = np.zeros(passable.shape, dtype=bool)
    goals[2, 2, 2] = True
    goals[0, 0, 0] = True
    field = DistanceField(passable, (2, 2, 2), VOXEL, goals=goals)
    np.testing.assert_array_equal(field.nearest_goal, [2, 2, 2])


def test_blocked_goal_is_skipped_for_a_reachable_one() -> None:
    passable = np.ones((10, 3, 3), dtype=bool)
    passable[2, 1, 1] = False
    goals = np.zeros(passable.shape, dtype=bool)
    goals[2, 1, 1] = True  # nearer but not passable
    goals[7, 1, 1] = True
    field = DistanceField(passable, (0, 1, 1), VOXEL, goals=goals)
    np.testing.assert_array_equal(field.nearest_goal, [7, 1, 1])



@pytest.mark.parametrize("seed", range(4))
def test_goals_turned_down_as_reached_give_the_field_of_the_accepted_goals(seed: int) -> None:
    """A goal `accept` turns down is searched on through as a plain voxel: the field, the goal
    found and its path are those of a search given only the accepted goals."""
    rng = np.random.default_rng(seed)
    passable = rng.random((24, 20, 6)) > 0.25
    start = np.argwhere(passable)[0]
    goals = passable & (rng.random(passable.shape) < 0.05)
    accepted = goals & (rng.random(passable.shape) < 0.2)
    nearest = DistanceField(passable, start, VOXEL, goals=goals).nearest_goal
    assert nearest is not None
    accepted[tuple(nearest)] = False  # at least one goal is turned down
    asked: list[tuple[int, ...]] = []

    def accept(voxel: npt.NDArray[np.int64]) -> bool:
        asked.append(tuple(int(v) for v in voxel))
        return bool(accepted[tuple(voxel)])

    lazy = DistanceField(passable, start, VOXEL, goals=goals, accept=accept)
    eager = DistanceField(passable, start, VOXEL, goals=accepted)
    assert eager.nearest_goal is not None
    np.testing.assert_array_equal(lazy.nearest_goal, eager.nearest_goal)
    np.testing.assert_array_equal(lazy.dist_m, eager.dist_m)
    np.testing.assert_array_equal(lazy.path_to(eager.nearest_goal),
                                  eager.path_to(eager.nearest_goal))
    # Asked nearest first, each goal once, and none beyond the answer.
    assert len(set(asked)) == len(asked) > 1
    assert asked[-1] == tuple(int(v) for v in eager.nearest_goal)
    distances = [lazy.dist_m[v] for v in asked]
    assert distances == sorted(distances)


def test_no_accepted_goal_searches_everything_reachable() -> None:
    passable = np.ones((8, 8, 3), dtype=bool)
    goals = np.zeros(passable.shape, dtype=bool)
    goals[::3, ::3, :] = True
    field = DistanceField(passable, (0, 0, 0), VOXEL, goals=goals, accept=lambda v: False)
    assert field.nearest_goal is None
    assert np.isfinite(field.dist_m).all()


# -- corners -------------------------------------------------------------------------------------


def test_diagonal_step_does_not_cut_a_blocked_corner_in_2d() -> None:
    passable = np.ones((3, 3, 1), dtype=bool)
    passable[1, 0, 0] = False
    field = DistanceField(passable, (0, 0, 0), VOXEL)
    # The direct diagonal would graze (1, 0, 0): the way round is two straight steps.
    assert field.dist_m[1, 1, 0] == pytest.approx(2 * VOXEL)
    path = field.path_to((1, 1, 0))
    np.testing.assert_array_equal(path, [[0, 0, 0], [0, 1, 0], [1, 1, 0]])


def test_diagonal_step_does_not_cut_a_blocked_corner_in_3d() -> None:
    # A 2 x 2 x 2 block whose only missing voxel is (1, 1, 0): the space diagonal from (0, 0, 0)
    # to (1, 1, 1) spans it, so the way is a face diagonal then a straight step, or the reverse.
    passable = np.ones((2, 2, 2), dtype=bool)
    passable[1, 1, 0] = False
    field = DistanceField(passable, (0, 0, 0), VOXEL)
    assert field.dist_m[1, 1, 1] == pytest.approx((SQRT2 + 1) * VOXEL)
    assert field.dist_m[1, 1, 1] > SQRT3 * VOXEL
    path = field.path_to((1, 1, 1))
    assert len(path) == 3
    assert_chain(path, passable, (0, 0, 0), (1, 1, 1))


def test_corner_rule_matches_the_reference_on_a_cluttered_grid() -> None:
    rng = np.random.default_rng(3)
    passable = rng.random((9, 8, 6)) > 0.3
    start = (0, 0, 0)
    passable[start] = True
    field = DistanceField(passable, start, VOXEL)
    reference = reference_distances(passable, start) * VOXEL
    assert np.array_equal(np.isinf(field.dist_m), np.isinf(reference))
    finite = np.isfinite(reference)
    assert np.count_nonzero(finite) > 50
    np.testing.assert_allclose(field.dist_m[finite], reference[finite], rtol=1e-12)


# -- segment_clear and shortcut -------------------------------------------------------------------


def test_segment_clear() -> None:
    mask = np.ones((6, 6, 1), dtype=bool)
    mask[3, 3, 0] = False
    a = np.array([0.5, 0.5, 0.5])
    assert segment_clear(mask, a, np.array([5.5, 0.5, 0.5]))
    assert not segment_clear(mask, a, np.array([5.5, 5.5, 0.5]))  # through (3, 3, 0)
    assert segment_clear(mask, a, a)
    # Leaving the grid is never clear.
    assert not segment_clear(mask, a, np.array([6.5, 0.5, 0.5]))
    assert not segment_clear(mask, a, np.array([0.5, -0.5, 0.5]))


def _l_corridor() -> BoolGrid:
    """A one-voxel corridor along x at y = 0, then along y at x = 9."""
    passable = np.zeros((10, 10, 1), dtype=bool)
    passable[:, 0, 0] = True
    passable[9, :, 0] = True
    return passable


def test_shortcut_keeps_the_ends_and_cuts_an_l_corridor_to_its_corner() -> None:
    passable = _l_corridor()
    start, goal = (0, 0, 0), (9, 9, 0)
    path = DistanceField(passable, start, VOXEL).path_to(goal)
    assert_chain(path, passable, start, goal)
    assert len(path) == 19
    short = shortcut(path, passable)
    assert short.shape[1] == 3
    assert len(short) < len(path)
    assert tuple(short[0]) == start
    assert tuple(short[-1]) == goal
    np.testing.assert_array_equal(short, [[0, 0, 0], [9, 0, 0], [9, 9, 0]])
    centres = short.astype(np.float64) + 0.5
    for a, b in itertools.pairwise(centres):
        assert segment_clear(passable, a, b)
    # Every kept point is a point of the original path, in the same order.
    rows = [int(np.flatnonzero(np.all(path == p, axis=1))[0]) for p in short]
    assert rows == sorted(rows)


def test_shortcut_of_an_open_path_is_its_ends() -> None:
    passable = np.ones((8, 8, 8), dtype=bool)
    path = DistanceField(passable, (0, 0, 0), VOXEL).path_to((7, 5, 2))
    assert len(path) == 8
    short = shortcut(path, passable)
    np.testing.assert_array_equal(short, [[0, 0, 0], [7, 5, 2]])


def test_shortcut_of_short_paths_is_unchanged() -> None:
    passable = np.ones((3, 3, 3), dtype=bool)
    for path in (np.zeros((0, 3), dtype=np.int64), np.array([[1, 1, 1]]),
                 np.array([[0, 0, 0], [1, 1, 1]])):
        np.testing.assert_array_equal(shortcut(path, passable), path)


def test_shortcut_around_a_pillar_stays_clear() -> None:
    passable = np.ones((12, 12, 1), dtype=bool)
    passable[4:8, 4:8, 0] = False
    start, goal = (0, 0, 0), (11, 11, 0)
    path = DistanceField(passable, start, VOXEL).path_to(goal)
    assert_chain(path, passable, start, goal)
    short = shortcut(path, passable)
    assert 2 < len(short) < len(path)
    assert tuple(short[0]) == start
    assert tuple(short[-1]) == goal
    centres = short.astype(np.float64) + 0.5
    for a, b in itertools.pairwise(centres):
        assert segment_clear(passable, a, b)


# -- nearest_traversable -------------------------------------------------------------------------


def test_nearest_traversable_returns_the_voxel_itself() -> None:
    traversable = np.zeros((10, 10, 10), dtype=bool)
    traversable[4, 4, 4] = True
    traversable[4, 4, 5] = True
    found = nearest_traversable(traversable, np.array([4, 4, 4]))
    assert found is not None
    assert found.dtype == np.int64
    np.testing.assert_array_equal(found, [4, 4, 4])


def test_nearest_traversable_finds_the_nearest_within_reach() -> None:
    traversable = np.zeros((10, 10, 10), dtype=bool)
    traversable[5, 5, 7] = True  # 2 away
    traversable[5, 8, 5] = True  # 3 away
    traversable[7, 7, 7] = True  # 2 * sqrt(3) away
    found = nearest_traversable(traversable, np.array([5, 5, 5]))
    np.testing.assert_array_equal(found, [5, 5, 7])
    # The first voxel is farther than reach 1: nothing.
    assert nearest_traversable(traversable, np.array([5, 5, 5]), reach=1) is None
    found = nearest_traversable(traversable, np.array([5, 5, 5]), reach=2)
    np.testing.assert_array_equal(found, [5, 5, 7])


def test_nearest_traversable_outside_the_grid() -> None:
    traversable = np.zeros((6, 6, 6), dtype=bool)
    traversable[0, 2, 2] = True
    found = nearest_traversable(traversable, np.array([-2, 2, 2]))
    np.testing.assert_array_equal(found, [0, 2, 2])
    assert nearest_traversable(traversable, np.array([-10, 2, 2])) is None


def test_nearest_traversable_none_when_nothing_is_traversable() -> None:
    traversable = np.zeros((6, 6, 6), dtype=bool)
    assert nearest_traversable(traversable, np.array([3, 3, 3])) is None
    traversable[0, 0, 0] = True
    assert nearest_traversable(traversable, np.array([5, 5, 5])) is None
    np.testing.assert_array_equal(
        nearest_traversable(traversable, np.array([3, 3, 3])), [0, 0, 0]
    )


def test_searches_in_a_row_do_not_see_each_other() -> None:
    """Searches share their buffers: one stopped early, one bounded by cost and one full, in any
    order, each give what the reference gives alone."""
    rng = np.random.default_rng(3)
    passable = rng.random((14, 12, 6)) < 0.8
    starts = [tuple(int(v) for v in s) for s in np.argwhere(passable)[[0, 40, 200]]]
    goals = np.zeros_like(passable)
    goals[tuple(np.argwhere(passable)[300])] = True
    for start in starts * 2:
        early = DistanceField(passable, start, VOXEL, goals=goals)
        bounded = DistanceField(passable, start, VOXEL, max_cost_m=0.35)
        full = DistanceField(passable, start, VOXEL)
        reference = reference_distances(passable, start) * VOXEL
        np.testing.assert_allclose(full.dist_m, reference, atol=1e-9)
        near = bounded.dist_m <= 0.35
        np.testing.assert_allclose(bounded.dist_m[near], reference[near], atol=1e-9)
        if early.nearest_goal is not None:
            goal = tuple(int(v) for v in early.nearest_goal)
            assert early.distance_to(goal) == pytest.approx(reference[goal])
            assert_chain(early.path_to(goal), passable, start, goal)
        for voxel in np.argwhere(passable)[::37]:
            assert full.distance_to(voxel) == pytest.approx(reference[tuple(voxel)])


def test_grid_path_snaps_both_ends_and_goes_round_a_wall() -> None:
    """From a vehicle beside a wall to a target just across it, both within the wall's safety
    margin: both ends snap to traversable voxels, the shortcut path goes through the wall's gap,
    and the goal voxel is returned; one shared voxel or no way through gives None."""
    state = np.full((40, 30, 10), VoxelState.FREE, dtype=np.uint8)
    state[20, :, :] = VoxelState.OCCUPIED
    state[20, 24:28, :] = VoxelState.FREE  # the only gap, at y = 2.4-2.8 m
    view = stack_from_state(state, 0.1, 0.15).view()
    here, there = np.array([1.95, 0.55, 0.55]), np.array([2.15, 0.55, 0.55])
    assert not view.traversable[19, 5, 5] and not view.traversable[21, 5, 5]
    found = grid_path(view, PathCache(), here, there)
    assert found is not None
    path, goal = found
    assert path[0][0] < 19 and goal[0] > 21  # snapped away from the wall, on either side
    np.testing.assert_array_equal(path[-1], goal)
    assert np.all(view.traversable[tuple(path.T)])
    assert path[:, 1].max() >= 24  # up to the gap: the straight way is walled
    for a, b in itertools.pairwise(path):  # and every leg clear
        assert segment_clear(view.traversable, a + 0.5, b + 0.5)
    assert grid_path(view, PathCache(), np.array([0.55, 0.55, 0.55]),
                     np.array([0.56, 0.56, 0.55])) is None  # one voxel
    state[20, 24:28, :] = VoxelState.OCCUPIED
    closed = stack_from_state(state, 0.1, 0.15).view()
    assert grid_path(closed, PathCache(), here, there) is None


@pytest.mark.parametrize("seed", range(3))
def test_the_nearest_goals_path_kept_at_the_end_is_the_whole_fields(seed: int) -> None:
    """The nearest goal's path and length, read from the search's buffers before they are
    cleaned, are those of a search over everything reachable (whose settled voxels' parents
    are the same); every other voxel is answered from the sorted visited voxels, in any order
    of the queries."""
    rng = np.random.default_rng(40 + seed)
    passable = rng.random((20, 18, 6)) > 0.3
    start = np.argwhere(passable)[0]
    goals = passable & (rng.random(passable.shape) < 0.02)
    goals[tuple(start)] = False
    near = DistanceField(passable, start, VOXEL, goals=goals)
    whole = DistanceField(passable, start, VOXEL)
    goal = near.nearest_goal
    assert goal is not None and len(near.path_to(goal)) > 2
    np.testing.assert_array_equal(near.path_to(goal), whole.path_to(goal))
    assert near.distance_to(goal) == whole.distance_to(goal) == whole.dist_m[tuple(goal)]
    # Other voxels the goal search settled: the same answers, asked before and after dist_m.
    settled = np.argwhere(near.dist_m <= near.distance_to(goal))
    assert len(settled) > 10
    for voxel in settled[rng.permutation(len(settled))[:20]]:
        np.testing.assert_array_equal(near.path_to(voxel), whole.path_to(voxel))
        assert near.distance_to(voxel) == whole.distance_to(voxel)
    fresh = DistanceField(passable, start, VOXEL, goals=goals)
    unreached = np.argwhere(~np.isfinite(near.dist_m))[0]
    assert fresh.distance_to(unreached) == np.inf and len(fresh.path_to(unreached)) == 0
    np.testing.assert_array_equal(fresh.dist_m, near.dist_m)
