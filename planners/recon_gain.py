"""Reconstruction gain of a camera pose: how much a view would add to the surface reconstruction.

ESM-Recon (Schmid et al., RA-L 2020, reconstruction gain) scores a view by the visible surface
voxels, each by the share a new measurement would take of the voxel's TSDF weight,
w_new / (w_new + w), counted only above a minimum impact, plus the unobserved voxels in view.
Here the rays are those of `planners.gain` (the same `RayGrid`, the same marching): a sample in
an unknown voxel counts its volume, exactly as the volumetric gain does; a ray that hits an
occupied voxel stops there and adds that surface voxel's worth

    surface_weight * impact(w) + direction_bonus * [the ray's azimuth sector is new to the voxel
                                                    and it was seen from < min_directions sectors]

with impact(w) = w_new / (w_new + w) (0 below `min_impact`), w the voxel's `surface_weight`
layer (TSDF-fused frames) and the sector bits read from `surface_directions`. The direction term
is our choice: a surface seen from one side only is poorly reconstructed there however often it
was seen. Both terms stop once a surface is seen well enough (`min_impact`, `min_directions`),
so that well-seen surfaces nearby do not hold the vehicle back from unexplored space. A surface
voxel counts as the volume of a one-voxel-thick patch of the ray's cell (r² dΩ voxel_size), so a
surface voxel fully worth observing weighs as much as an unknown voxel, as in the paper, where
every visible voxel counts once.
"""

from __future__ import annotations

import math

import numba
import numpy as np
import numpy.typing as npt

from planners.gain import FloatArray, GainEvaluator
from planners.surface_gaps import CLOSED_GAP
from sim.camera import CameraConfig
from sim.map_view import MapView
from sim.occupancy import VoxelState

ByteGrid = npt.NDArray[np.uint8]

_UNKNOWN = np.uint8(VoxelState.UNKNOWN)
_OCCUPIED = np.uint8(VoxelState.OCCUPIED)
_CLOSED_GAP = CLOSED_GAP
_SECTORS = 8


def column_sector_bits(azimuths: FloatArray) -> ByteGrid:
    """(A,) the `surface_directions` bit of a surface seen along each column's azimuth: the
    direction from the surface back to the camera is the azimuth plus pi."""
    back = np.mod(np.asarray(azimuths, dtype=np.float64) + math.pi, 2.0 * math.pi)
    sector = np.minimum((back / (2.0 * math.pi / _SECTORS)).astype(np.int64), _SECTORS - 1)
    bits: ByteGrid = (1 << sector).astype(np.uint8)
    return bits


@numba.njit(cache=True)
def _recon_column_gains(
    state: ByteGrid,
    weight: ByteGrid,
    seen_from: ByteGrid,
    origin: FloatArray,
    voxel_size: float,
    position: FloatArray,
    directions: FloatArray,
    solid_angles: FloatArray,
    sector_bits: ByteGrid,
    step_m: float,
    min_range_m: float,
    max_range_m: float,
    unknown_weight: float,
    surface_weight: float,
    direction_bonus: float,
    new_weight: float,
    min_impact: float,
    min_directions: int,
) -> FloatArray:
    """(A,) reconstruction gain (m³ equivalents) of each azimuth column from `position` (3,).

    state, weight, seen_from: (nx, ny, nz) uint8 layers; directions: (E, A, 3);
    solid_angles: (E,); sector_bits: (A,) uint8.
    """
    nx, ny, nz = state.shape
    rows, cols = directions.shape[0], directions.shape[1]
    out = np.zeros(cols)
    n_steps = int(np.floor((max_range_m - min_range_m) / step_m))
    for e in range(rows):
        w = solid_angles[e] * step_m
        for a in range(cols):
            dx, dy, dz = directions[e, a, 0], directions[e, a, 1], directions[e, a, 2]
            acc = 0.0
            for s in range(n_steps):
                r = min_range_m + (s + 0.5) * step_m
                i = int(np.floor((position[0] + r * dx - origin[0]) / voxel_size))
                j = int(np.floor((position[1] + r * dy - origin[1]) / voxel_size))
                k = int(np.floor((position[2] + r * dz - origin[2]) / voxel_size))
                if i < 0 or j < 0 or k < 0 or i >= nx or j >= ny or k >= nz:
                    break
                v = state[i, j, k]
                if v == _CLOSED_GAP:
                    break
                if v == _OCCUPIED:
                    impact = new_weight / (new_weight + float(weight[i, j, k]))
                    worth = surface_weight * impact if impact >= min_impact else 0.0
                    mask = seen_from[i, j, k]
                    if (mask & sector_bits[a]) == 0:
                        count = 0
                        for b in range(_SECTORS):
                            count += (mask >> b) & 1
                        if count < min_directions:
                            worth += direction_bonus
                    acc += worth * r * r * solid_angles[e] * voxel_size
                    break
                if v == _UNKNOWN:
                    acc += unknown_weight * r * r * w
            out[a] += acc
    return out


class ReconGainEvaluator(GainEvaluator):
    """Reconstruction gain of a pose on the current map; the yaw handling (columns, window
    sums, best yaw) is `GainEvaluator`'s.

    Args:
        unknown_weight: weight of unknown volume (1: the volumetric gain).
        surface_weight: weight of a surface voxel's TSDF impact.
        direction_bonus: worth of a surface voxel seen from a new azimuth sector.
        new_weight: TSDF weight one more frame would add (w_new).
        min_impact: impacts below this count as nothing.
        min_directions: a surface voxel seen from at least this many sectors earns no
            direction bonus.
    """

    # A closed gap stops a ray with no worth: it is no surface a view could reconstruct.
    gap_fill = int(CLOSED_GAP)

    def __init__(self, camera: CameraConfig, angle_step_deg: float, step_m: float,
                 max_range_m: float | None = None, *, unknown_weight: float = 1.0,
                 surface_weight: float = 1.0, direction_bonus: float = 0.5,
                 new_weight: float = 1.0, min_impact: float = 0.2,
                 min_directions: int = 2) -> None:
        super().__init__(camera, angle_step_deg, step_m, max_range_m)
        self.unknown_weight = unknown_weight
        self.surface_weight = surface_weight
        self.direction_bonus = direction_bonus
        self.new_weight = new_weight
        self.min_impact = min_impact
        self.min_directions = min_directions
        self.sector_bits = column_sector_bits(self.rays.azimuths)

    def columns(self, view: MapView, position: npt.ArrayLike,
                state: ByteGrid | None = None) -> FloatArray:
        """(A,) reconstruction gain per azimuth column around `position` (world (3,)); `state`
        (nx, ny, nz) replaces the view's voxel states, as in `GainEvaluator.columns`."""
        self.evaluations += 1
        return _recon_column_gains(
            view.state if state is None else state, view.surface_weight, view.surface_directions,
            np.asarray(view.origin, dtype=np.float64), float(view.voxel_size),
            np.asarray(position, dtype=np.float64), self.rays.directions,
            self.rays.solid_angles, self.sector_bits, self.step_m, self.min_range_m,
            self.max_range_m, self.unknown_weight, self.surface_weight, self.direction_bonus,
            self.new_weight, self.min_impact, self.min_directions)
