"""Giving up frontier targets that stay frontiers however often the vehicle looks at them.

Some frontier voxels never clear: seen too steeply, through a gap narrower than a voxel, or at
the edge of the sensor's range. A planner that keeps choosing them flies back and forth for
ever. `GiveUpTracker` counts arrivals at a target's viewpoint that left the target a frontier,
and after `after` of them masks a cube around the target, which the planner then leaves out.
"""

from __future__ import annotations

import numpy as np

from planners.api import Observation, PlanOutcome
from planners.search import BoolGrid, IndexArray


class GiveUpTracker:
    """Visit counts per target voxel and the mask of given-up voxels of one episode."""

    def __init__(self, after: int, radius_voxels: int) -> None:
        self.after = after
        self.radius_voxels = radius_voxels
        self.visits: dict[tuple[int, int, int], int] = {}
        self._mask: BoolGrid | None = None

    @property
    def mask(self) -> BoolGrid | None:
        """(nx, ny, nz) True on given-up voxels; None before the first `update`."""
        return self._mask

    def update(self, here: IndexArray, goal: IndexArray | None, target: IndexArray | None,
               obs: Observation) -> BoolGrid:
        """Count an arrival of the vehicle (at voxel `here`) at the previous plan's `goal`
        viewpoint if its `target` is still a frontier, and give the target up at the
        `after`-th such arrival. Returns the mask (made on the first call, from the map's
        shape); `goal` or `target` None (no previous target) counts nothing."""
        if self._mask is None:
            self._mask = np.zeros(obs.map.shape, dtype=np.bool_)
        if goal is None or target is None:
            return self._mask
        # Within one voxel counts: the estimated pose ends near the viewpoint, not always in it.
        arrived = obs.last_outcome == PlanOutcome.REACHED and np.max(np.abs(here - goal)) <= 1
        t = target
        if not arrived or not obs.map.frontier[t[0], t[1], t[2]]:
            return self._mask
        key = (int(t[0]), int(t[1]), int(t[2]))
        self.visits[key] = self.visits.get(key, 0) + 1
        if self.visits[key] >= self.after:
            r = self.radius_voxels
            # Slicing clips the high edge; the low edge must not go negative (wrap-around).
            lo = np.maximum(t - r, 0)
            hi = t + r + 1
            self._mask[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]] = True
        return self._mask
