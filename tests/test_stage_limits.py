"""benchmarks/stage_limits.py: the bare 3D-DDA that stands for the occupancy update's limit
visits exactly the voxels each ray crosses."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.stage_limits import _dda_visits


def _crossed(origin: npt.NDArray[np.float64], end: npt.NDArray[np.float64],
             shape: tuple[int, int, int]) -> set[tuple[int, int, int]]:
    """The in-grid unit voxels (grid origin 0) the segment origin -> end passes through, by the
    slab test of every voxel."""
    crossed = set()
    d = end - origin
    with np.errstate(divide="ignore", invalid="ignore"):
        for idx in np.ndindex(*shape):
            lo = np.array(idx, dtype=np.float64)
            t0 = (lo - origin) / d
            t1 = (lo + 1.0 - origin) / d
            near = np.where(d == 0.0, np.where((origin >= lo) & (origin <= lo + 1), -np.inf,
                                                np.inf), np.minimum(t0, t1))
            far = np.where(d == 0.0, np.where((origin >= lo) & (origin <= lo + 1), np.inf,
                                               -np.inf), np.maximum(t0, t1))
            if max(near.max(), 0.0) <= min(far.min(), 1.0):
                crossed.add(idx)
    return crossed


@pytest.mark.parametrize("seed", range(10))
def test_the_bare_dda_visits_the_voxels_each_ray_crosses(seed: int) -> None:
    rng = np.random.default_rng(seed)
    shape = (7, 6, 5)
    origin = rng.uniform(-1.0, 8.0, 3)
    ends = rng.uniform(-2.0, 9.0, (6, 3))
    for end in ends:
        counts = np.zeros(shape, dtype=np.uint32)
        visits = _dda_visits(origin, end[None, :], np.zeros(3), 1.0, counts)
        visited = {tuple(int(v) for v in i) for i in np.argwhere(counts)}
        assert visits == len(visited) == int(counts.sum())  # each voxel once per ray
        assert visited == _crossed(origin, end, shape)
