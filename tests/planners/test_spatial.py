"""The grid-hash spatial index against brute-force distance queries."""

from __future__ import annotations

import numpy as np
import pytest

from planners.spatial import SpatialIndex


def test_radius_and_nearest_queries_match_brute_force() -> None:
    rng = np.random.default_rng(0)
    points = rng.uniform(-5, 5, size=(400, 3))
    index = SpatialIndex(cell_m=0.7)
    ids = [index.insert(p, value=float(i), yaw=0.1 * i) for i, p in enumerate(points)]
    assert ids == list(range(400))
    removed = set(range(0, 400, 7))
    for i in removed:
        index.remove(i)
    alive = np.array(sorted(set(range(400)) - removed))
    assert len(index) == len(alive)
    assert index.ids().tolist() == alive.tolist()
    for q in rng.uniform(-6, 6, size=(50, 3)):
        d = np.linalg.norm(points[alive] - q, axis=1)
        for r in (0.3, 1.0, 2.5):
            assert index.within(q, r).tolist() == alive[d <= r].tolist()
        assert index.nearest(q) == alive[int(np.argmin(d))]
        near = index.nearest(q, max_radius=0.5)
        assert near == (alive[int(np.argmin(d))] if d.min() <= 0.5 else None)


def test_values_and_updates() -> None:
    index = SpatialIndex(1.0)
    a = index.insert([0.0, 0.0, 0.0], value=2.0, yaw=1.0)
    index.update(a, 3.0)
    assert index.value(a) == 3.0 and index.yaw(a) == 1.0
    index.update(a, 1.5, yaw=-1.0)
    assert index.values(index.ids()).tolist() == [1.5]
    assert index.yaw(a) == -1.0
    assert np.allclose(index.points(index.ids()), [[0.0, 0.0, 0.0]])
    index.remove(a)
    index.remove(a)  # twice is harmless
    assert len(index) == 0 and index.nearest([0.0, 0.0, 0.0]) is None
    with pytest.raises(ValueError):
        SpatialIndex(0.0)
