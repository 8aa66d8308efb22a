"""Points by grid cell (`sim.cell_lists`): the within-distance count against a k-d tree."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from sim.cell_lists import cell_lists, share_within


def _kd_share(points: np.ndarray, queries: np.ndarray, bound: float) -> float:
    dist, _ = cKDTree(points).query(queries, k=1, distance_upper_bound=bound)
    return float(np.count_nonzero(np.isfinite(dist))) / len(queries)


def test_share_within_agrees_with_a_kd_tree() -> None:
    rng = np.random.default_rng(5)
    for spread in (0.3, 3.0, 40.0):
        points = rng.uniform(-spread, spread, size=(5_000, 3))
        queries = np.vstack([rng.uniform(-spread, spread, size=(3_000, 3)),
                             points[:500] + rng.normal(0.0, 0.03, size=(500, 3))])
        for bound in (0.01, 0.05, 0.5):
            assert share_within(points, queries, bound) == _kd_share(points, queries, bound)


def test_a_distance_of_exactly_the_bound_does_not_count() -> None:
    """The bound is exclusive, as the k-d tree's `distance_upper_bound`: on a 5 cm lattice,
    neighbours at exactly 5 cm count only under a bound nudged past it."""
    lattice = np.stack(np.meshgrid(*[np.arange(10) * 0.05] * 3, indexing="ij"), -1)
    points = lattice.reshape(-1, 3)[::2]
    queries = lattice.reshape(-1, 3)[1::2]
    for bound in (0.05, float(np.nextafter(0.05, np.inf))):
        assert share_within(points, queries, bound) == _kd_share(points, queries, bound)
    assert share_within(points, queries, 0.05) < share_within(
        points, queries, float(np.nextafter(0.05, np.inf)))


def test_empty_clouds_and_the_lists() -> None:
    assert share_within(np.zeros((0, 3)), np.ones((4, 3)), 1.0) == 0.0
    assert share_within(np.ones((4, 3)), np.zeros((0, 3)), 1.0) == 0.0
    points = np.array([[0.0, 0.0, 0.0], [0.05, 0.0, 0.0], [1.0, 1.0, 1.0], [0.01, 0.0, 0.0]])
    lists = cell_lists(points, np.arange(4), points.min(axis=0), points.max(axis=0), 0.1, 1)
    cells = np.floor((points - lists.origin) / lists.cell).astype(np.int64)
    flat = np.ravel_multi_index(cells.T, lists.shape)
    for c in np.unique(flat):
        members = lists.members[lists.start[c]:lists.start[c + 1]]
        np.testing.assert_array_equal(members, np.flatnonzero(flat == c))
    assert lists.start[-1] == 4
    assert lists.start.dtype == np.int32  # half the table's memory below 2^31 points
