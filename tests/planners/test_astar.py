"""A* on the voxel grid against Dijkstra's distance field, and the path cache."""

from __future__ import annotations

import numpy as np
import pytest

from planners.astar import PathCache, astar
from planners.search import DistanceField, _workspace

VOXEL = 0.1


def _random_grid(seed: int, shape: tuple[int, int, int], density: float) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.random(shape) > density


@pytest.mark.parametrize("seed", range(6))
def test_astar_length_equals_dijkstra(seed: int) -> None:
    passable = _random_grid(seed, (18, 16, 9), 0.3)
    rng = np.random.default_rng(100 + seed)
    free = np.argwhere(passable)
    start = tuple(free[rng.integers(len(free))])
    field = DistanceField(passable, start, VOXEL)
    for goal in free[rng.choice(len(free), size=25, replace=False)]:
        path, length = astar(passable, start, goal, VOXEL)
        expected = field.dist_m[tuple(goal)]
        if not np.isfinite(expected):
            assert len(path) == 0 and length == np.inf
            continue
        assert length == pytest.approx(expected, abs=1e-9)
        assert tuple(path[0]) == start and tuple(path[-1]) == tuple(goal)
        steps = np.diff(path, axis=0)
        assert np.all(np.abs(steps) <= 1) and np.all(np.any(steps != 0, axis=1))
        assert np.all(passable[path[:, 0], path[:, 1], path[:, 2]])
        # The path's own length is the reported one.
        assert np.sum(np.linalg.norm(steps, axis=1)) * VOXEL == pytest.approx(length)


def test_astar_searches_in_a_row_share_clean_buffers() -> None:
    """A* reuses Dijkstra's per-thread buffers: found paths, unreachable goals (which flood the
    start's component) and distance fields in any order give what each gives alone, and every
    search leaves the buffers clean."""
    passable = _random_grid(7, (16, 14, 7), 0.35)
    free = np.argwhere(passable)
    rng = np.random.default_rng(7)
    starts = [tuple(int(v) for v in free[i]) for i in rng.choice(len(free), 3, replace=False)]
    fields = {s: DistanceField(passable, s, VOXEL).dist_m.copy() for s in starts}
    unreachable = 0
    for start in starts * 2:
        for goal in free[rng.choice(len(free), size=15, replace=False)]:
            path, length = astar(passable, start, goal, VOXEL)
            expected = fields[start][tuple(goal)]
            if np.isfinite(expected):
                assert length == pytest.approx(expected, abs=1e-9)
                assert tuple(path[-1]) == tuple(goal)
            else:
                unreachable += 1
                assert len(path) == 0 and length == np.inf
        np.testing.assert_allclose(DistanceField(passable, start, VOXEL).dist_m, fields[start])
        ws = _workspace(passable.size)
        assert np.all(np.isinf(ws.dist)) and np.all(ws.parent == -1) and not ws.done.any()
    assert unreachable > 0  # the grid has closed pockets: the flooding case was exercised


def test_astar_does_not_cut_corners() -> None:
    passable = np.ones((3, 3, 1), dtype=bool)
    passable[1, 0, 0] = False
    passable[0, 1, 0] = False
    path, length = astar(passable, (0, 0, 0), (1, 1, 0), VOXEL)
    assert len(path) == 0 and length == np.inf


def test_astar_rejects_blocked_ends_and_outside_points() -> None:
    passable = np.ones((4, 4, 4), dtype=bool)
    passable[3, 3, 3] = False
    assert len(astar(passable, (0, 0, 0), (3, 3, 3), VOXEL)[0]) == 0
    with pytest.raises(ValueError):
        astar(passable, (0, 0, 0), (4, 0, 0), VOXEL)


def test_cache_reuses_a_passable_path_and_drops_a_blocked_one() -> None:
    passable = np.ones((12, 5, 3), dtype=bool)
    cache = PathCache()
    first, length = cache.path(passable, (0, 2, 1), (11, 2, 1), VOXEL)
    again, _ = cache.path(passable, (0, 2, 1), (11, 2, 1), VOXEL)
    assert again is first
    assert (cache.hits, cache.misses) == (1, 1)
    # Block the straight corridor in the middle: the cached path is no longer returned.
    passable[6, 2, 1] = False
    detour, longer = cache.path(passable, (0, 2, 1), (11, 2, 1), VOXEL)
    assert cache.misses == 2
    assert not any(tuple(p) == (6, 2, 1) for p in detour)
    assert longer > length


def test_cache_evicts_the_least_recently_used() -> None:
    passable = np.ones((6, 6, 2), dtype=bool)
    cache = PathCache(max_entries=2)
    for goal in ((5, 0, 0), (5, 5, 0), (0, 5, 0)):
        cache.path(passable, (0, 0, 0), goal, VOXEL)
    cache.path(passable, (0, 0, 0), (5, 0, 0), VOXEL)
    assert cache.hits == 0  # the first goal was evicted
