"""ESM growing its tree while the vehicle flies: `esm-ipp-v4` and `esm-recon-v4`.

`esm-ipp-v3` (`planners.esm_horizon`) grows its tree by one batch at every call, and every call
is made at a segment's end with the vehicle hovering until it returns. The original planner
(ethz-asl/mav_active_3d_planning, `OnlinePlanner::loopIteration` with `expand_batch: 1` and
`min_new_segments`, `min_new_tries`, `min_new_value` all 0 in `exploration_planner.yaml`) expands
its tree continuously while the vehicle flies, from the segment being flown toward (the root it
has already moved to), and when that segment's end is reached requests the next one at once:
selection and the tree's updates, no expansion.

v4 does the same within the framework's call points:

- **In flight**: the planner asks to be called `first_growth_s` after each flight's departure
  (`Plan.replan_s`); that call grows the tree by one batch of v3's size (`tries_per_call`,
  `new_per_call`), its semilocal samples drawn round the node being flown to, while the vehicle
  flies on (`Plan.keep`, not asked again during that flight). The tree grows by as much per
  flight as v3's, but the time charged for it elapses in flight, not hovering.
- **At a segment's end**: the tree is re-rooted and re-checked as in v3 and the best branch
  chosen; it grows there only when no branch is worth flying (the first call, or when the
  original would call its back-tracker while expanding on).
"""

from __future__ import annotations

import dataclasses
from typing import Literal

from pydantic import Field

from planners.api import Observation, Plan, PlanOutcome
from planners.esm import FloatArray
from planners.esm_horizon import EsmHorizonPlanner
from planners.esm_horizon_config import EsmHorizonV3Config
from planners.segment_tree import SegmentTree


class EsmContinuousConfig(EsmHorizonV3Config):
    """`EsmHorizonV3Config` and when the growing call is made in flight."""

    # Ours: the framework asks a planner mid-leg at a set time (`Plan.replan_s`), where the
    # original expands without pause; one batch, as soon as the flight is under way, keeps
    # v3's growth per flight and so its planning cost.
    first_growth_s: float = Field(0.1, gt=0.0)


class EsmReconContinuousConfig(EsmContinuousConfig):
    """ESM-Recon v4: `EsmContinuousConfig` with the reconstruction gain."""

    gain: Literal["volumetric", "reconstruction"] = "reconstruction"


class EsmContinuous(EsmHorizonPlanner):
    """`esm-ipp-v4`: v3 growing its tree in flight (module doc)."""

    config_model = EsmContinuousConfig
    config: EsmContinuousConfig

    def plan(self, obs: Observation) -> Plan:
        if obs.last_outcome == PlanOutcome.FLYING:
            return self._grow_in_flight(obs)
        plan = super().plan(obs)
        if plan.done:
            return plan
        return dataclasses.replace(plan, replan_s=self.config.first_growth_s)

    def _grow_in_flight(self, obs: Observation) -> Plan:
        """One batch of growth while the vehicle flies on; not asked again this flight."""
        tree = self.tree
        if tree is None:
            return Plan(keep=True, info={"mode": "grow", "added": 0})
        self._view = obs.map
        self._gain_state = None
        added = self._expand(tree, obs)
        return Plan(keep=True, info={"mode": "grow", "added": added, "nodes": int(tree.size)})

    def _grow_and_select(self, tree: SegmentTree, obs: Observation) -> tuple[int, int, float]:
        """At a segment's end the original selects at once; the tree grows here only when no
        branch is worth flying."""
        if tree.size >= 2:
            child, value = self.select(tree, obs.map, obs.time)
            if child >= 0 and value > self.config.min_value:
                return 0, child, value
        return super()._grow_and_select(tree, obs)

    def _sampling_centre(self, tree: SegmentTree) -> FloatArray:
        """In flight, the node being flown to (the original's root has moved there when the
        segment was requested); at rest, the root."""
        pending = self._pending
        if 0 <= pending < tree.size:
            centre: FloatArray = tree.positions[pending]
            return centre
        return super()._sampling_centre(tree)


class EsmReconContinuous(EsmContinuous):
    """`esm-recon-v4`: `esm-ipp-v4` with the reconstruction gain."""

    config_model = EsmReconContinuousConfig
