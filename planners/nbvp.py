"""NBVP: receding-horizon next-best-view planning (Bircher et al., ICRA 2016).

At each iteration a random tree grows from the vehicle in known traversable space
(`planners.nbv_tree`), sampled in a box around the vehicle, with edges of at most
`extension_m`; each node sees the unknown volume of its camera view, discounted by
exp(-lambda * path cost) and accumulated along its branch. The tree grows until it has
`min_nodes` nodes (N_init) and some node sees unknown volume; only the first edge of the best
branch is flown, and the rest of the branch seeds the next tree. Exploration ends only when the
tree reaches `max_nodes` nodes (N_tol) without any gain. When the tree cannot grow at all, the
vehicle goes back to the previous iteration's position, as the original does. When the best local
branch is worth less than `wide_below_gain_m3`, a tree sampled in the whole area is grown too,
and the vehicle follows whichever best branch is worth more.

That sampling box, the second tree and the closed surface gaps below are nbvp-v1's additions;
nbvp-v2, the published method, turns all three off (`NbvpV2Config`): one tree sampled in the
whole area, the gain cast through the map as it is.

Gain counts the unknown voxels that rays reach through free and unknown space. Rays grazing a
wall sweep some voxels of its occupied layer free, and through such holes the gain's rays reach
the wall's interior, unknown for ever: views near walls keep a gain that no flight can reduce,
and the vehicle roams the explored part of the area after it. So nbvp-v1 casts the gain through a
copy of the map whose occupied surfaces have gaps up to `surface_gap_m` closed.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Literal

import numpy as np
import numpy.typing as npt
from pydantic import Field

from planners.api import Observation, Plan, Planner, PlannerConfig, PlannerContext
from planners.astar import PathCache
from planners.gain import GainEvaluator
from planners.nbv_tree import (
    StateGrid,
    TreeOutcome,
    TreeSettings,
    grow_tree,
)
from planners.surface_gaps import close_surface_gaps
from planners.waypoints import grid_path, path_waypoints, tree_root

FloatArray = npt.NDArray[np.float64]


class NbvpConfig(PlannerConfig):
    """NBVP's settings. Unless noted, defaults are those of the public NBVP configuration the
    benchmark's authors used on MAZE (`nbvp/...` keys of its `maze.yaml`)."""

    # nbvp/tree/extension_range: 1.5
    extension_m: float = Field(1.5, gt=0.0, description="RRT extension range, m")
    # Half-size of the sampling box around the vehicle (clipped to the area), m; None samples
    # the whole area. Our choice: the gain range (nbvp/gain/range, 5 m), beyond which a node's
    # gain is discounted by exp(-0.5 x 5) < 0.1 anyway. The public NBVP samples a ball around
    # the vehicle as wide as the exploration box's diagonal, i.e. the whole box; in MAZE's
    # corridors few such samples pull the tree through a doorway (docs/planners.md).
    sampling_radius_m: float | None = Field(5.0, gt=0.0)
    # nbvp/tree/initial_iterations: 15
    min_nodes: int = Field(15, ge=1)
    # nbvp/tree/cuttoff_iterations: 400
    max_nodes: int = Field(400, ge=1)
    # NBVP returns to the previous position after 1000 * (nodes + 1) failed samples.
    max_failures_per_node: int = Field(1000, ge=1)
    # nbvp/gain/degressive_coeff: 0.5
    degressive_coeff: float = Field(0.5, ge=0.0, description="lambda, 1/m")
    # What the best branch must be worth, m³, for gain to be found. The original starts the
    # root's value at nbvp/gain/zero (1 in the authors' maze.yaml) and finds gain when a branch
    # is worth more than that, i.e. when any node sees any unknown volume: 0 here, whatever
    # nbvp/gain/zero is. (AEP sets its own threshold.)
    zero_gain: float = Field(0.0, ge=0.0, description="m³")
    # nbvp/gain/range: 5.0 (the camera's range)
    gain_range_m: float | None = Field(5.0, gt=0.0)
    # NBVP samples a random yaw per node.
    yaw: Literal["random", "best"] = "random"
    # RRT in NBVP; RRT* when set (AEP).
    rewire_radius_m: float | None = Field(None, gt=0.0)
    # Our choice: 5° rays resolve a 0.2 m voxel at 2.3 m; the original visits every voxel.
    ray_step_deg: float = Field(5.0, gt=0.0, le=30.0)
    # When the best local branch is worth less than this, m³, a tree sampled in the whole area
    # is grown as well (until a branch is worth this much, or `max_nodes`), and the better of
    # the two best branches is flown; None: only when no local gain is found at all. Our choice:
    # on MAZE the vehicle stuck in the explored part of the maze followed branches worth
    # 0.0002-0.08 m³ (partly seen pockets inside the sampling box) while the unexplored part lay
    # beyond the box; 0.1 m³ is just above those. Only used with a sampling box, and inert
    # when at most `zero_gain` (AEP's 1 m³): a branch found to gain is then worth more.
    wide_below_gain_m3: float | None = Field(0.1, gt=0.0)
    # Gaps up to this wide, m, between occupied voxels along an axis are closed for the gain's
    # rays (None: rays pass them, as in the original). Our choice: on MAZE the vehicle stalled
    # (a traced run: 0.89 at 700 s) following branches worth 0.02-3 m³, mostly the unknown
    # interior of its 0.25 m walls, seen through holes in their occupied layer; closing 0.3 m
    # gaps removes much of it, and only gaps far narrower than the vehicle (0.9 m) close.
    surface_gap_m: float | None = Field(0.3, gt=0.0)

    def tree_settings(self) -> TreeSettings:
        return TreeSettings(
            extension_m=self.extension_m, sampling_radius_m=self.sampling_radius_m,
            min_nodes=self.min_nodes, max_nodes=self.max_nodes,
            max_failures_per_node=self.max_failures_per_node,
            degressive_coeff=self.degressive_coeff, zero_gain=self.zero_gain,
            rewire_radius_m=self.rewire_radius_m, yaw=self.yaw,
        )


class NbvpV2Config(NbvpConfig):
    """nbvp-v2: the published method. nbvp-v1's three additions of ours are off, so the tree
    samples the whole area and the gain is cast through the map as it is; whatever stall that
    leaves is the method's own (`docs/planners/nbvp.md`)."""

    # The public NBVP samples a ball around the vehicle as wide as the exploration box's
    # diagonal (`nbvp/...` settings of the authors' maze.yaml): the whole area.
    sampling_radius_m: float | None = Field(None, gt=0.0)
    # No second, whole-area tree: there is one tree, sampled in the whole area.
    wide_below_gain_m3: float | None = Field(None, gt=0.0)
    # Rays pass gaps between occupied voxels, as in the original.
    surface_gap_m: float | None = Field(None, gt=0.0)


class NbvpPlanner(Planner):
    """The code of every NBVP version (and of AEP's local step); `config_model` picks the
    version."""

    config_model = NbvpConfig
    config: NbvpConfig

    def reset(self, ctx: PlannerContext) -> None:
        super().reset(ctx)
        self._gains: GainEvaluator | None = None
        self._seed: FloatArray | None = None  # (M, 4) rest of the last best branch
        self._previous: list[FloatArray] = []  # roots of past iterations
        self._paths = PathCache()
        self._gain_state: StateGrid | None = None  # (nx, ny, nz) states the gain is cast through

    def gain_evaluator(self, voxel_size: float) -> GainEvaluator:
        if self._gains is None:
            self._gains = GainEvaluator(self.context.camera, self.config.ray_step_deg,
                                        voxel_size, self.config.gain_range_m)
        return self._gains

    def plan(self, obs: Observation) -> Plan:
        here = np.asarray(obs.pose.position, dtype=np.float64)
        root, snapped = tree_root(obs.map, obs.pose.position)
        if root is None:
            return Plan.finished("the vehicle is not in traversable space")
        self._gain_state = self._closed_surfaces(obs)
        outcome = self.grow(obs, root)
        if outcome.best >= 0 and outcome.gain_found:
            wide = self._wide_if_better(obs, root, outcome)
            if wide is not None:
                return self._first_edge(wide, snapped, obs, mode="wide",
                                        local_value=outcome.best_value)
            return self._first_edge(outcome, snapped, obs)
        self._seed = None
        if outcome.stalled:
            # The tree cannot grow from here: go back the way the vehicle came, as NBVP does.
            while self._previous:
                back = self._path_to(obs, self._previous.pop())
                if back is not None:
                    return Plan(back, info={"mode": "back", "nodes": int(outcome.tree.size)})
        self._previous.append(here.copy())
        return self.no_local_gain(obs, outcome)

    def grow(self, obs: Observation, root: FloatArray) -> TreeOutcome:
        ctx = self.context
        return grow_tree(obs.map, self.gain_evaluator(obs.map.voxel_size),
                         self.config.tree_settings(), ctx.rng, root, obs.pose.yaw,
                         ctx.bounds_min, ctx.bounds_max, self._seed, self._gain_state)

    def _closed_surfaces(self, obs: Observation) -> StateGrid | None:
        """(nx, ny, nz) map states with narrow gaps in occupied surfaces closed, for the gain
        (None: the map's own)."""
        gap = self.config.surface_gap_m
        if gap is None:
            return None
        return close_surface_gaps(obs.map.state, round(gap / obs.map.voxel_size))

    def _wide_if_better(self, obs: Observation, root: FloatArray,
                        local: TreeOutcome) -> TreeOutcome | None:
        """A tree sampled in the whole area, if the best local branch is worth less than
        `wide_below_gain_m3` and that tree's best branch is worth more (None otherwise). The
        tree grows until a branch is worth `wide_below_gain_m3`, or up to `max_nodes`."""
        cfg = self.config
        threshold = cfg.wide_below_gain_m3
        if threshold is None or cfg.sampling_radius_m is None or local.best_value >= threshold:
            return None
        ctx = self.context
        settings = replace(cfg.tree_settings(), sampling_radius_m=None,
                           zero_gain=max(cfg.zero_gain, threshold))
        wide = grow_tree(obs.map, self.gain_evaluator(obs.map.voxel_size), settings, ctx.rng,
                         root, obs.pose.yaw, ctx.bounds_min, ctx.bounds_max,
                         gain_state=self._gain_state)
        if wide.best < 0 or wide.best_value <= local.best_value:
            return None
        return wide

    def no_local_gain(self, obs: Observation, outcome: TreeOutcome) -> Plan:
        """What to do when no branch is worth `zero_gain`: NBVP stops, but only once a tree
        sampled in the whole area, as the original samples, finds no gain either (a box around
        the vehicle misses unknown space beyond it, e.g. at the end of an explored dead end)."""
        if self.config.sampling_radius_m is not None:
            wide, outcome = self._grow_wide(obs, outcome)
            if wide is not None:
                return wide
        plan = Plan.finished(f"no branch gains more than {self.config.zero_gain} m³ in "
                             f"{outcome.tree.size - 1} nodes")
        plan.info.update(nodes=int(outcome.tree.size), stalled=str(outcome.stalled))
        return plan

    def _grow_wide(self, obs: Observation,
                   local: TreeOutcome) -> tuple[Plan | None, TreeOutcome]:
        """The first edge of a tree sampled in the whole area (None if it finds no gain either),
        and that tree (the local one if none could be grown)."""
        root, snapped = tree_root(obs.map, obs.pose.position)
        if root is None:
            return None, local
        ctx = self.context
        settings = replace(self.config.tree_settings(), sampling_radius_m=None)
        outcome = grow_tree(obs.map, self.gain_evaluator(obs.map.voxel_size), settings, ctx.rng,
                            root, obs.pose.yaw, ctx.bounds_min, ctx.bounds_max,
                            gain_state=self._gain_state)
        if outcome.best < 0 or not outcome.gain_found:
            return None, outcome
        if self._previous:
            self._previous.pop()  # `plan` recorded this position; `_first_edge` records it again
        plan = self._first_edge(outcome, snapped, obs)
        plan.info["mode"] = "wide"
        return plan, outcome


    def _first_edge(self, outcome: TreeOutcome, snapped: bool, obs: Observation,
                    mode: str = "local", local_value: float | None = None) -> Plan:
        tree = outcome.tree
        branch = tree.branch(outcome.best)
        nodes = np.column_stack([tree.positions[branch], tree.yaws[branch]])
        self._seed = nodes[2:].copy() if len(nodes) > 2 else None
        self._previous.append(np.asarray(obs.pose.position, dtype=np.float64).copy())
        waypoints = nodes[1:2].copy()
        if snapped:
            first = np.array([[*tree.positions[0], waypoints[0, 3]]])
            waypoints = np.vstack([first, waypoints])
        plan = Plan(waypoints, info={
            "mode": mode, "nodes": int(tree.size), "best_value": outcome.best_value,
            "best_gain": float(tree.gains[outcome.best]),
        })
        if local_value is not None:
            plan.info["local_value"] = local_value
        return plan

    def _path_to(self, obs: Observation, target: FloatArray,
                 yaw: float | None = None) -> FloatArray | None:
        """(N, 4) waypoints of a shortest grid path to `target`, or None if unreachable."""
        view = obs.map
        found = grid_path(view, self._paths, obs.pose.position, target)
        if found is None:
            return None
        path, goal = found
        look = target if yaw is None else view.index_to_world(goal[None])[0] + np.array(
            [np.cos(yaw), np.sin(yaw), 0.0])
        waypoints: FloatArray = path_waypoints(view, path, obs.pose.position, look)
        return waypoints


class Nbvp(NbvpPlanner):
    """nbvp-v1: with three additions of ours (the 5 m sampling box with a whole-area tree
    beside it, and surface gaps closed for the gain)."""

    config_model = NbvpConfig
    config: NbvpConfig


class NbvpV2(NbvpPlanner):
    """nbvp-v2: the published method."""

    config_model = NbvpV2Config
    config: NbvpV2Config
