"""Thinning a recording's surface snapshot: the first point of each cell, in the points' order,
as sorting the cells' keys gives it."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pytest

from sim.point_thinning import first_in_each_cell


def by_sorting(points: npt.NDArray[np.float64], cell_m: float) -> npt.NDArray[np.float64]:
    cells = np.floor(points / cell_m).astype(np.int64)
    cells -= cells.min(axis=0)
    span = cells.max(axis=0) + 1
    keys = (cells[:, 0] * span[1] + cells[:, 1]) * span[2] + cells[:, 2]
    _, first = np.unique(keys, return_index=True)
    return points[np.sort(first)]


@pytest.mark.parametrize("count", [1, 2, 9, 5000])
@pytest.mark.parametrize("cell_m", [0.1, 0.25])
def test_the_first_point_of_each_cell_in_order(count: int, cell_m: float) -> None:
    rng = np.random.default_rng(count)
    # Rounded to centimetres, so that many points share a cell and some lie on cell faces.
    points = np.round(rng.uniform(-3.0, 5.0, size=(count, 3)), 2)
    assert np.array_equal(first_in_each_cell(points, cell_m), by_sorting(points, cell_m))


def test_no_points() -> None:
    assert first_in_each_cell(np.zeros((0, 3)), 0.1).shape == (0, 3)


def test_one_point_per_cell_stays() -> None:
    points = np.array([[0.05, 0.05, 0.05], [0.15, 0.05, 0.05], [0.06, 0.04, 0.01]])
    assert np.array_equal(first_in_each_cell(points, 0.1), points[:2])
