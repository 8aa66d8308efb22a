"""Fast random access to a recording's map over time.

`sim.recording.Recording.map_state_at` replays every keyframe from the start, which is fine once
but too slow for a slider scrubbed back and forth over a long run. `MapTimeline` replays the
keyframes once at load time, keeping a full copy of the map every `checkpoint_every` keyframes, so
the state at any keyframe costs one copy plus at most `checkpoint_every` delta applications.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from sim.recording import Recording

UNKNOWN, FREE, OCCUPIED = 0, 1, 2
# A checkpoint of the MAZE grid (200 x 200 x 25) is 1 MB; one every 30 keyframes (60 s at the
# default 2 s keyframe interval) keeps a 1800 s run at 30 MB and bounds a lookup to 30 deltas.
DEFAULT_CHECKPOINT_EVERY = 30
# Larger grids get sparser checkpoints so that one run's stay within this many bytes; the deltas
# in between are small (only changed voxels), so lookups stay fast.
CHECKPOINT_BUDGET_BYTES = 64 << 20


@dataclass(frozen=True)
class MapLayers:
    """What the viewer draws of the map at one keyframe.

    Attributes:
        keyframe: index of the keyframe (-1 before the first one).
        occupied: (N, 3) float32 world centres of occupied voxels.
        frontiers: (M, 3) float32 world centres of free voxels with an unknown 6-neighbour.
        known_voxels: number of voxels known free or occupied.
    """

    keyframe: int
    occupied: npt.NDArray[np.float32]
    frontiers: npt.NDArray[np.float32]
    known_voxels: int


def frontier_mask(state: npt.NDArray[np.uint8]) -> npt.NDArray[np.bool_]:
    """(nx, ny, nz) True at free voxels that have an unknown face neighbour inside the grid.

    Voxels outside the grid do not count as unknown: the grid covers the explorable box, and its
    border is not a frontier anyone can fly to.
    """
    unknown = state == UNKNOWN
    near_unknown = np.zeros_like(unknown)
    for axis in range(3):
        lo = [slice(None)] * 3
        hi = [slice(None)] * 3
        lo[axis], hi[axis] = slice(0, -1), slice(1, None)
        near_unknown[tuple(lo)] |= unknown[tuple(hi)]
        near_unknown[tuple(hi)] |= unknown[tuple(lo)]
    result: npt.NDArray[np.bool_] = (state == FREE) & near_unknown
    return result


class MapTimeline:
    """The recording's occupancy map at every keyframe, with checkpoints for quick access."""

    def __init__(self, recording: Recording, checkpoint_every: int | None = None) -> None:
        header = recording.header
        nx, ny, nz = (int(n) for n in header["grid_shape"])
        self.shape: tuple[int, int, int] = (nx, ny, nz)
        self.voxel_size = float(header.get("voxel_size", 0.1))
        self.origin = np.asarray(header.get("grid_origin", (0.0, 0.0, 0.0)), dtype=np.float64)
        self.times: npt.NDArray[np.float64] = np.asarray(recording.array("keyframe_times"),
                                                         dtype=np.float64)
        self._offsets = np.asarray(recording.array("keyframe_offsets"), dtype=np.int64)
        self._indices = np.asarray(recording.array("keyframe_indices"), dtype=np.int64)
        self._states = np.asarray(recording.array("keyframe_states"), dtype=np.uint8)
        if checkpoint_every is None:
            voxels = nx * ny * nz
            needed = -(-len(self.times) * voxels // CHECKPOINT_BUDGET_BYTES)
            checkpoint_every = max(DEFAULT_CHECKPOINT_EVERY, needed)
        self.checkpoint_every = max(1, int(checkpoint_every))
        self._checkpoints: dict[int, npt.NDArray[np.uint8]] = {}
        self.known_counts = self._replay()

    def _replay(self) -> npt.NDArray[np.int64]:
        """Apply every keyframe once: store checkpoints and the known-voxel count after each."""
        state = np.zeros(int(np.prod(self.shape)), dtype=np.uint8)
        counts = np.zeros(len(self.times), dtype=np.int64)
        known = 0
        for k in range(len(self.times)):
            idx, val = self._delta(k)
            # Only the changed voxels can change the count: compare their before and after.
            known += int(np.count_nonzero(val)) - int(np.count_nonzero(state[idx]))
            state[idx] = val
            counts[k] = known
            if k % self.checkpoint_every == 0:
                self._checkpoints[k] = state.copy()
        return counts

    def _delta(self, k: int) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.uint8]]:
        lo, hi = int(self._offsets[k]), int(self._offsets[k + 1])
        return self._indices[lo:hi], self._states[lo:hi]

    def keyframe_at(self, time: float) -> int:
        """Index of the last keyframe at or before `time`; -1 before the first."""
        return int(np.searchsorted(self.times, time, side="right")) - 1

    def state(self, keyframe: int) -> npt.NDArray[np.uint8]:
        """(nx, ny, nz) map state after `keyframe` (all unknown for -1)."""
        if keyframe < 0:
            return np.zeros(self.shape, dtype=np.uint8)
        base = keyframe - keyframe % self.checkpoint_every
        state = self._checkpoints[base].copy()
        for k in range(base + 1, keyframe + 1):
            idx, val = self._delta(k)
            state[idx] = val
        return state.reshape(self.shape)

    def known_volume_m3(self, time: float) -> float:
        """Volume of the voxels known free or occupied at `time`, m³."""
        k = self.keyframe_at(time)
        return 0.0 if k < 0 else float(self.known_counts[k]) * self.voxel_size ** 3

    def centres(self, mask: npt.NDArray[np.bool_]) -> npt.NDArray[np.float32]:
        """(N, 3) world centres of the voxels set in `mask`."""
        ijk = np.argwhere(mask)
        centres = self.origin + (ijk + 0.5) * self.voxel_size
        return centres.astype(np.float32)

    def layers(self, keyframe: int) -> MapLayers:
        state = self.state(keyframe)
        known = 0 if keyframe < 0 else int(self.known_counts[keyframe])
        return MapLayers(keyframe=keyframe, occupied=self.centres(state == OCCUPIED),
                         frontiers=self.centres(frontier_mask(state)), known_voxels=known)
