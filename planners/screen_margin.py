"""The rounding margin of the compiled screens (`planners.rrt`'s tree samples,
`planners.esm_screen`'s tries): where a quantity lies this near to where the screened Python
code's decision flips, the screen leaves the decision to that code.

1e-6 (voxel units or metres, relative above 1) is far above the last-bit differences between a
compiled sum and NumPy's (or BLAS's) on the same inputs, and far below any distance the methods
decide on.
"""

from __future__ import annotations

import math

import numba

MARGIN = 1e-6


@numba.njit(cache=True, inline="always")
def near_value(x: float, threshold: float) -> bool:
    """`x` within the margin of `threshold` (relative to it above 1)."""
    return abs(x - threshold) <= MARGIN * (abs(threshold) + 1.0)


@numba.njit(cache=True, inline="always")
def near_integer(x: float) -> bool:
    """`x` within the margin of a whole number: a coordinate on a voxel face, or a sample count
    that rounding could change."""
    return abs(x - math.floor(x + 0.5)) < MARGIN
