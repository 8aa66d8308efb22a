"""benchmarks/unexplored.py: coverage over time, unexplored volume by height and by region."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

# The benchmark scripts are not an installed package: they run from the project folder.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.unexplored import by_height, over_time, regions


class _Recording:
    """Two keyframes: half the grid known at 10 s, all of it but one corner at 20 s."""

    def __init__(self, shape: tuple[int, int, int]) -> None:
        self.shape = shape
        self.pose_times = np.arange(0.0, 20.01, 0.5)
        self.poses = np.column_stack([np.zeros((len(self.pose_times), 2)),
                                      self.pose_times / 10.0, np.zeros(len(self.pose_times))])

    def map_state_at(self, time: float) -> np.ndarray:
        state = np.zeros(self.shape, dtype=np.uint8)
        if time >= 10.0:
            state[: self.shape[0] // 2] = 1
        if time >= 20.0:
            state[:] = 1
            state[:2, :2, :2] = 0
        return state


def test_coverage_over_time_and_what_is_left_where() -> None:
    shape = (10, 10, 10)
    observable = np.ones(shape, dtype=bool)
    rec = _Recording(shape)
    series = over_time(rec, observable, interval=10.0)
    assert [r["t_s"] for r in series] == [10.0, 20.0]
    assert series[0]["coverage"] == pytest.approx(0.5)
    assert series[1]["coverage"] == pytest.approx(1 - 8 / 1000)
    assert (series[1]["z_min_m"], series[1]["z_max_m"]) == (pytest.approx(1.05), 2.0)

    missed = observable & (rec.map_state_at(np.inf) == 0)
    bands = by_height(observable, missed, z0=0.0, voxel=0.5, band=1.0)
    assert [b["z_from_m"] for b in bands] == [0.0, 1.0, 2.0, 3.0, 4.0]
    assert bands[0]["unexplored_m3"] == pytest.approx(8 * 0.125)
    assert bands[0]["observable_m3"] == pytest.approx(200 * 0.125)
    assert sum(b["unexplored_m3"] for b in bands[1:]) == 0.0

    found = regions(missed, origin=np.array([1.0, 2.0, 3.0]), voxel=0.5)
    assert len(found) == 1
    assert found[0]["volume_m3"] == pytest.approx(1.0)
    assert found[0]["box_min_m"] == [1.0, 2.0, 3.0]
    assert found[0]["box_max_m"] == [2.0, 3.0, 4.0]
    assert regions(np.zeros(shape, dtype=bool), np.zeros(3), 0.5) == []
