"""Closing narrow gaps in occupied surfaces for a gain's rays: the linear kernel against a
brute-force reference, and what the closed gaps are worth to each gain."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pytest

from planners.gain import GainEvaluator
from planners.recon_gain import ReconGainEvaluator
from planners.surface_gaps import CLOSED_GAP, close_surface_gaps
from sim.camera import CameraConfig
from sim.occupancy import VoxelState
from tests.planners.conftest import stack_from_state

VOXEL = 0.1
CAMERA = CameraConfig()
HERE = np.array([3.05, 2.05, 1.05])


def _reference(state: npt.NDArray[np.uint8], gap: int, fill: int) -> npt.NDArray[np.uint8]:
    """Every voxel that is not occupied itself, with an occupied voxel a below and one b above
    along some axis, a + b <= gap + 1, set to `fill`: the definition, checked pair by pair."""
    occupied = state == VoxelState.OCCUPIED
    mask = np.zeros_like(occupied)
    for axis in range(3):
        n = state.shape[axis]
        for a in range(1, gap + 1):
            for b in range(1, gap + 2 - a):
                below = np.zeros_like(occupied)
                above = np.zeros_like(occupied)
                dst, src = [slice(None)] * 3, [slice(None)] * 3
                dst[axis], src[axis] = slice(a, n), slice(0, n - a)
                below[tuple(dst)] = occupied[tuple(src)]
                dst[axis], src[axis] = slice(0, n - b), slice(b, n)
                above[tuple(dst)] = occupied[tuple(src)]
                mask |= below & above
    out = state.copy()
    out[mask & ~occupied] = fill
    return out


@pytest.mark.parametrize("gap", [1, 2, 3, 5])
@pytest.mark.parametrize("seed", [0, 1])
def test_kernel_matches_the_definition(gap: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    state = rng.choice(np.array([0, 1, 2], dtype=np.uint8), p=[0.4, 0.4, 0.2],
                       size=(23, 17, 11))
    for fill in (int(VoxelState.OCCUPIED), int(CLOSED_GAP)):
        closed = close_surface_gaps(state, gap, fill)
        np.testing.assert_array_equal(closed, _reference(state, gap, fill))
        assert closed is not state
    assert np.any(close_surface_gaps(state, gap) != state)


def test_no_gap_changes_nothing() -> None:
    state = np.random.default_rng(3).integers(0, 3, size=(9, 8, 7)).astype(np.uint8)
    np.testing.assert_array_equal(close_surface_gaps(state, 0), state)


def _wall_with_a_hole() -> npt.NDArray[np.uint8]:
    """Known free round HERE; a 0.3 m thick wall at x = 5.0-5.3 m with an unknown interior and
    one-voxel holes in the near face's occupied layer; unknown beyond."""
    state = np.full((80, 40, 25), VoxelState.FREE, dtype=np.uint8)
    state[50:53] = VoxelState.UNKNOWN  # the wall's interior
    state[50] = VoxelState.OCCUPIED
    state[53] = VoxelState.OCCUPIED
    state[54:] = VoxelState.UNKNOWN
    state[50, 15:25:3, 5:20:3] = VoxelState.FREE  # holes swept by grazing rays
    return state


def test_closed_gaps_remove_the_wall_interior_from_both_gains() -> None:
    state = _wall_with_a_hole()
    stack = stack_from_state(state, VOXEL, 0.45)
    stack.surface._weight[...] = 200  # every surface seen often, from every side
    stack.surface._directions[...] = 0xFF
    view = stack.view()
    volumetric = GainEvaluator(CAMERA, 5.0, VOXEL)
    recon = ReconGainEvaluator(CAMERA, 5.0, VOXEL)
    for gains in (volumetric, recon):
        through_holes = gains.at_yaw(gains.columns(view, HERE), 0.0)
        closed = close_surface_gaps(view.state, 3, gains.gap_fill)
        assert through_holes > 0.0
        assert gains.at_yaw(gains.columns(view, HERE, closed), 0.0) == 0.0
        assert gains.best_view(view, HERE).gain >= through_holes
        assert gains.best_view(view, HERE, closed).gain == 0.0


def test_a_closed_gap_is_no_surface_to_the_reconstruction_gain() -> None:
    """Filled as occupied, the never-fused interior would count as a surface worth seeing;
    filled as CLOSED_GAP it stops the ray and is worth nothing."""
    state = _wall_with_a_hole()
    stack = stack_from_state(state, VOXEL, 0.45)
    stack.surface._weight[...] = 200
    stack.surface._directions[...] = 0xFF
    stack.surface._weight[50:54] = np.where(state[50:54] == VoxelState.OCCUPIED, 200, 0)
    view = stack.view()
    recon = ReconGainEvaluator(CAMERA, 5.0, VOXEL)
    as_occupied = close_surface_gaps(view.state, 3, int(VoxelState.OCCUPIED))
    as_closed = close_surface_gaps(view.state, 3, recon.gap_fill)
    assert recon.gap_fill == int(CLOSED_GAP)
    assert recon.at_yaw(recon.columns(view, HERE, as_occupied), 0.0) > 0.0
    assert recon.at_yaw(recon.columns(view, HERE, as_closed), 0.0) == 0.0
