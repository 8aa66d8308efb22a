"""Two layout seeds of a generated area differ in their layout, not only by jitter: at least
`MIN_LAYOUT_DIFFERENCE` of their occupied voxels differ (the small, fast areas here; the
benchmark `benchmarks/heldout_difference.py` measures every one)."""

from __future__ import annotations

import numpy as np
import pytest

from areas.layout_difference import (
    MIN_LAYOUT_DIFFERENCE,
    GridMismatchError,
    layout_difference,
    occupied_difference,
)
from areas.registry import generate_area, load_area

# Seeds as the held-out split draws them: large, unrelated numbers.
SEEDS = (0, 5_871_042_356_118_823_901, 912_334_870_001)


def test_the_share_counts_differing_occupied_voxels() -> None:
    a = np.zeros((4, 4, 4), dtype=bool)
    b = a.copy()
    a[0, :, :] = True  # 16 voxels
    b[0, :2, :] = True  # 8 of them
    b[3, 0, 0] = True  # and one more
    assert occupied_difference(a, b) == pytest.approx(9 / 17)
    assert occupied_difference(a, a) == 0.0
    assert occupied_difference(np.zeros_like(a), np.zeros_like(a)) == 0.0
    with pytest.raises(GridMismatchError):
        occupied_difference(a, np.zeros((4, 4, 5), dtype=bool))


@pytest.mark.parametrize("family", ["maze", "powerplant", "platform-b", "offices-a"])
def test_seeds_of_a_family_differ_by_the_documented_share(family: str) -> None:
    areas = [generate_area(family, seed) for seed in SEEDS]
    for i in range(len(areas)):
        for j in range(i + 1, len(areas)):
            assert layout_difference(areas[i], areas[j]) >= MIN_LAYOUT_DIFFERENCE, (family, i, j)


def test_seed_zero_is_the_registered_scene() -> None:
    assert generate_area("powerplant", 0).content_hash == load_area("powerplant").content_hash
    assert layout_difference(generate_area("maze", 0), load_area("maze")) == 0.0


def test_areas_on_other_grids_are_refused() -> None:
    with pytest.raises(GridMismatchError):
        layout_difference(load_area("maze"), load_area("powerplant"))
