"""Giving up frontier targets that stay frontiers however often the vehicle looks at them.

Some frontier voxels never clear: seen too steeply, through a gap narrower than a voxel, or at
the edge of the sensor's range. A planner that keeps choosing them flies back and forth for
ever. `GiveUpTracker` counts arrivals at a target's viewpoint that left the target a frontier,
and after `after` of them masks a cube around the target, which the planner then leaves out.

With `view_reach_m` set, an arrival also counts every other frontier voxel the camera looks at
from there: Yamauchi's robot adds the frontier it reached to its list of visited frontiers
after sensing all around, and goes on to the nearest unvisited one. A frontier voxel is looked
at when it lies in the camera's view within `view_reach_m` and the line of sight to one of its
unknown face neighbours crosses no occupied voxel: the camera would have seen into the unknown
there, so a voxel still a frontier after `after` such arrivals is one the sensor cannot clear
(the unknown inside a floor slab below a floor voxel that grazing rays left free, say), given
up on its own (no cube: it was looked at, its neighbours were not necessarily).
"""

from __future__ import annotations

import numpy as np

from planners.api import Observation, PlanOutcome
from planners.frontiers import frontiers_in_view
from planners.search import BoolGrid, IndexArray
from planners.viewpoints import sees_into_unknown
from sim.camera import CameraConfig


class GiveUpTracker:
    """Visit counts per target voxel and the mask of given-up voxels of one episode.

    Args:
        after: arrivals that left a voxel a frontier before it is given up.
        radius_voxels: half-width of the cube given up around a target.
        camera, view_reach_m: with both, every frontier voxel looked at from an arrival counts
            too (see the module's docstring); None keeps the target alone.
    """

    def __init__(self, after: int, radius_voxels: int, *, camera: CameraConfig | None = None,
                 view_reach_m: float | None = None) -> None:
        self.after = after
        self.radius_voxels = radius_voxels
        self.camera = camera
        self.view_reach_m = view_reach_m if camera is not None else None
        self.visits: dict[tuple[int, int, int], int] = {}
        self._mask: BoolGrid | None = None
        self._looks: np.ndarray | None = None  # (nx, ny, nz) uint8 arrivals a voxel was seen at

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
        if arrived and self.view_reach_m is not None:
            self._count_looked_at(obs)
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

    def _count_looked_at(self, obs: Observation) -> None:
        """Count the frontier voxels looked at from the vehicle's pose; give up those looked
        at from `after` arrivals."""
        assert self.camera is not None and self.view_reach_m is not None and self._mask is not None
        view = obs.map
        if self._looks is None:
            self._looks = np.zeros(view.shape, dtype=np.uint8)
        voxels, _ = frontiers_in_view(view, obs.pose, self.camera, self.view_reach_m)
        voxels = voxels[~self._mask[voxels[:, 0], voxels[:, 1], voxels[:, 2]]]
        if len(voxels) == 0:
            return
        eye = (np.asarray(obs.pose.position, dtype=np.float64) - view.origin) / view.voxel_size
        looked = voxels[sees_into_unknown(view, np.repeat(eye[None], len(voxels), axis=0),
                                          voxels)]
        i, j, k = looked[:, 0], looked[:, 1], looked[:, 2]
        self._looks[i, j, k] = np.minimum(self._looks[i, j, k], 254) + 1
        done = self._looks[i, j, k] >= self.after
        self._mask[i[done], j[done], k[done]] = True
