"""AEP: autonomous exploration planning (Selin et al., RA-L 2019).

Local exploration as in NBVP, with an RRT* tree whose nodes look along their best yaw; nodes
whose view gains more than `zero_gain` are cached in a spatial index. When no local branch is
worth `zero_gain`, the cached nodes are re-evaluated on the current map (best first, by their
cached gain discounted by the straight-line distance, an upper bound of their worth) and the
vehicle flies a shortest grid path to the one with the best gain * exp(-lambda * path length).
When no cached node gains more than `zero_gain`, Classic's nearest frontier takes over, and
Classic's own end condition ends the exploration (aep-v2 with classic-v1's settings, aep-v3 with
classic-v2's); aep-v1 ends the exploration there.

aep-v4 takes its global step as the public code the FLYBO authors ran does (`aeplanner`'s
`getFrontiers`, `pigain`'s `pig.py`, `rrtplanner` and their `rpl_exploration_rotors` loop): the
goals are the cached nodes whose cached gain exceeds `goal_gain_m3` (16 m³), cached gains are
refreshed only near the vehicle (within `reevaluate_range_m`, every `reevaluate_period_s`, those
above `reevaluate_above_m3`), the nearest goal by path is flown to, and with no goal left the
vehicle hovers and the planner is asked again, as that loop asks again, rather than ending.

Every version is one class, `AepPlanner`, configured by `AepBaseConfig`; a version is a config
model that sets the defaults of the settings it differs in (`fallback`, and v4's global step),
and none is a subclass of another. A later change of behaviour is a new setting whose default in
`AepV1Config` and `AepConfig` keeps what they do, and a new version that sets it.
"""

from __future__ import annotations

import heapq
import math
from typing import ClassVar, Literal

import numpy as np
from pydantic import Field

from planners.api import FloatArray, Observation, Plan, PlannerContext
from planners.classic import ClassicConfig, ClassicPlanner, ClassicV2Config, frontier_fallback
from planners.nbv_tree import TreeOutcome
from planners.nbvp import NbvpConfig, NbvpPlanner
from planners.spatial import SpatialIndex


def _flown_m(here: FloatArray, waypoints: FloatArray) -> float:
    """Length, m, of the polyline from `here` through the (N, 4) waypoints' positions."""
    return float(np.sum(np.linalg.norm(np.diff(np.vstack([here, waypoints[:, :3]]), axis=0),
                        axis=1)))


class AepBaseConfig(NbvpConfig):
    """AEP's settings shared by its versions. Unless noted, defaults are those of the public
    AEP configuration the benchmark's authors used on MAZE (`aep/...` keys of its `maze.yaml`).
    Settings the versions differ in have no default here: each version's model sets it."""

    # aep/tree/extension_range: 1.5
    extension_m: float = Field(1.5, gt=0.0)
    # aep/tree/max_sampling_radius: 10
    sampling_radius_m: float | None = Field(10.0, gt=0.0)
    # aep/tree/initial_iterations: 15
    min_nodes: int = Field(15, ge=1)
    # aep/tree/cutoff_iterations: 30
    max_nodes: int = Field(30, ge=1)
    # aep/gain/lambda: 0.75
    degressive_coeff: float = Field(0.75, ge=0.0)
    # aep/gain/zero: 1
    zero_gain: float = Field(1.0, ge=0.0)
    # AEP's own global step (cached nodes, then A*) replaces NBVP's whole-area tree.
    wide_below_gain_m3: float | None = None
    # Our choice: AEP counts a view only above its `zero_gain` of 1 m³, more than the unknown
    # wall interior seen through holes that made NBVP stall; its gain is cast as published.
    surface_gap_m: float | None = None
    # aep/gain/r_max: 5
    gain_range_m: float | None = Field(5.0, gt=0.0)
    # AEP picks the best yaw of each node.
    yaw: Literal["random", "best"] = "best"
    # AEP grows an RRT*; our choice of radius: one extension range.
    rewire_radius_m: float | None = Field(1.5, gt=0.0)
    # raycast/dphi, raycast/dtheta: 10 (degrees)
    ray_step_deg: float = Field(10.0, gt=0.0, le=30.0)
    # Our choice: one cached node per half metre keeps the cache small; AEP caches every node.
    cache_spacing_m: float = Field(0.5, gt=0.0)
    # When the cache runs dry: Classic's nearest frontier with these settings (see
    # `_fall_back`), or None, which ends the exploration there (or hovers, `hover_when_no_goal`).
    fallback: ClassicConfig | None
    # The global step's rule. None (v1-v3, ours): every cached node is re-evaluated on the
    # current map, best first, and the best gain * exp(-lambda * path length) above
    # `zero_gain` is flown to. A number (v4): aeplanner's `getFrontiers` threshold: the goals
    # are the nodes whose cached gain exceeds it, and the nearest by path is flown to.
    goal_gain_m3: float | None = Field(None, ge=0.0)
    # pig.py's re-evaluation of cached gains (only with `goal_gain_m3`): every 5 s, the nodes
    # within 2 * aep/gain/r_max of the vehicle whose cached gain exceeds 2.
    reevaluate_period_s: float = Field(5.0, gt=0.0)
    reevaluate_range_m: float = Field(10.0, gt=0.0)
    reevaluate_above_m3: float = Field(2.0, ge=0.0)
    # rpl_exploration_rotors: with no goal, the loop asks the planner again at its 100 Hz rate
    # (the `break` leaves its `switch`, not its loop): the vehicle hovers, instead of falling
    # back or ending. With either global step.
    hover_when_no_goal: bool = False


class AepV1Config(AepBaseConfig):
    """aep-v1: the exploration ends when the cache runs dry."""

    fallback: ClassicConfig | None = None


class AepConfig(AepBaseConfig):
    """AEP's settings. Unless noted, defaults are those of the public AEP configuration the
    benchmark's authors used on MAZE (`aep/...` keys of its `maze.yaml`)."""

    # aep-v2, our choice: Classic's nearest frontier when the cache runs dry.
    fallback: ClassicConfig | None = ClassicConfig()


class AepV3Config(AepBaseConfig):
    """aep-v3: as aep-v2, with classic-v2's nearest frontier when the cache runs dry."""

    fallback: ClassicV2Config | None = ClassicV2Config()


class AepV4Config(AepBaseConfig):
    """aep-v4: the global step of the public code the FLYBO authors ran (module docstring);
    no fallback: with no goal the vehicle hovers and asks again."""

    fallback: ClassicConfig | None = None
    # aeplanner.cpp, getFrontiers: srv.request.threshold = 16
    goal_gain_m3: float | None = 16.0
    hover_when_no_goal: bool = True


class AepPlanner(NbvpPlanner):
    """The code of every AEP version; `config_model` picks the version (see the module's
    docstring)."""

    config_model: ClassVar[type[AepBaseConfig]] = AepBaseConfig
    config: AepBaseConfig

    def reset(self, ctx: PlannerContext) -> None:
        super().reset(ctx)
        self._cache = SpatialIndex(cell_m=max(self.config.cache_spacing_m, 0.5))
        self._fallback: ClassicPlanner | None = None
        self._reevaluated_at = -math.inf
        if self.config.fallback is not None:
            self._fallback = ClassicPlanner(self.config.fallback)
            self._fallback.reset(ctx)

    def grow(self, obs: Observation, root: FloatArray) -> TreeOutcome:
        outcome = super().grow(obs, root)
        self._remember(outcome)
        cfg = self.config
        if cfg.goal_gain_m3 is not None and (
                obs.time - self._reevaluated_at >= cfg.reevaluate_period_s):
            # pig.py's timer runs beside the planner whatever it does: at every call once due.
            self._reevaluate_near(obs, np.asarray(obs.pose.position, dtype=np.float64))
        return outcome

    def _remember(self, outcome: TreeOutcome) -> None:
        """Cache every node whose own view gains more than `zero_gain`; a node near a cached
        one refreshes that entry instead of adding another."""
        tree, cfg = outcome.tree, self.config
        for n in range(1, tree.size):
            gain = float(tree.gains[n])
            near = self._cache.nearest(tree.positions[n], cfg.cache_spacing_m)
            if near is not None:
                if gain > self._cache.value(near):
                    self._cache.update(near, gain, float(tree.yaws[n]))
                continue
            if gain > cfg.zero_gain:
                self._cache.insert(tree.positions[n], gain, float(tree.yaws[n]))

    def no_local_gain(self, obs: Observation, outcome: TreeOutcome) -> Plan:
        """Global step: fly to the cached node worth the most now (v1-v3), or to the nearest
        goal (v4)."""
        if self.config.goal_gain_m3 is not None:
            return self._nearest_goal(obs, self.config.goal_gain_m3)
        cfg, view = self.config, obs.map
        here = np.asarray(obs.pose.position, dtype=np.float64)
        gains = self.gain_evaluator(view.voxel_size)
        ids = self._cache.ids()
        if len(ids) == 0:
            return self._no_goal(obs, "no cached node left")
        dist = np.linalg.norm(self._cache.points(ids) - here, axis=1)
        # Upper bounds of each node's worth: gains only shrink as the map fills in, and a
        # path is never shorter than the straight line.
        bounds = self._cache.values(ids) * np.exp(-cfg.degressive_coeff * dist)
        heap = [(-float(b), int(i)) for b, i in zip(bounds, ids, strict=True)]
        heapq.heapify(heap)
        best: tuple[float, FloatArray] | None = None
        evaluated = 0
        while heap and (best is None or -heap[0][0] > best[0]):
            _, ident = heapq.heappop(heap)
            point = self._cache.point(ident)
            view_gain = gains.best_view(view, point)
            evaluated += 1
            if view_gain.gain <= cfg.zero_gain:
                self._cache.remove(ident)
                continue
            self._cache.update(ident, view_gain.gain, view_gain.yaw)
            waypoints = self._path_to(obs, point, view_gain.yaw)
            if waypoints is None:
                if np.linalg.norm(point - here) < self.config.cache_spacing_m:
                    # Standing on it already: its gain must come from turning on the spot.
                    waypoints = np.array([[*here, view_gain.yaw]])
                else:
                    self._cache.remove(ident)
                    continue
            length = _flown_m(here, waypoints)
            score = view_gain.gain * math.exp(-cfg.degressive_coeff * length)
            if best is None or score > best[0]:
                best = (score, waypoints)
        if best is None:
            return self._no_goal(obs, "no cached node gains more than the threshold")
        return Plan(best[1], info={"mode": "global", "candidates": len(ids),
                                   "evaluated": evaluated, "score": best[0]})

    def _nearest_goal(self, obs: Observation, threshold: float) -> Plan:
        """The published global step: a shortest path to the nearest cached node whose cached
        gain exceeds `threshold` (rrtplanner returns the least-cost path among the goals its
        tree reaches). Cached gains are refreshed near the vehicle only (`grow`); far nodes
        keep the gain they were cached with, as in pig.py."""
        cfg = self.config
        here = np.asarray(obs.pose.position, dtype=np.float64)
        ids = self._cache.ids()
        goals = ids[self._cache.values(ids) > threshold] if len(ids) else ids
        if len(goals) == 0:
            return self._no_goal(obs, f"no cached node gains more than {threshold:g} m³")
        dist = np.linalg.norm(self._cache.points(goals) - here, axis=1)
        best: tuple[float, FloatArray] | None = None
        for k in np.argsort(dist, kind="stable"):
            if best is not None and dist[k] >= best[0]:
                break  # a path is never shorter than the straight line
            ident = int(goals[k])
            point, yaw = self._cache.point(ident), self._cache.yaw(ident)
            if dist[k] < cfg.cache_spacing_m:
                waypoints: FloatArray | None = np.array([[*here, yaw]])  # turn on the spot
            else:
                waypoints = self._path_to(obs, point, yaw)
            if waypoints is None:
                # Ours: the original's tree would search until it reached a goal.
                self._cache.remove(ident)
                continue
            length = _flown_m(here, waypoints)
            if best is None or length < best[0]:
                best = (length, waypoints)
        if best is None:
            return self._no_goal(obs, f"no node gaining more than {threshold:g} m³ is reachable")
        return Plan(best[1], info={"mode": "global", "goals": len(goals),
                                   "path_m": best[0]})

    def _reevaluate_near(self, obs: Observation, here: FloatArray) -> None:
        """pig.py's timer: the gains of the cached nodes within `reevaluate_range_m` of the
        vehicle along each axis whose cached gain exceeds `reevaluate_above_m3`, cast again on
        the current map."""
        cfg = self.config
        self._reevaluated_at = obs.time
        gains = self.gain_evaluator(obs.map.voxel_size)
        ids = self._cache.ids()
        if len(ids) == 0:
            return
        # pig.py queries its R-tree with a box, not a ball, round the vehicle.
        near = np.all(np.abs(self._cache.points(ids) - here) <= cfg.reevaluate_range_m, axis=1)
        due = ids[near & (self._cache.values(ids) > cfg.reevaluate_above_m3)]
        for ident in due.tolist():
            view_gain = gains.best_view(obs.map, self._cache.point(ident))
            self._cache.update(ident, view_gain.gain, view_gain.yaw)

    def _no_goal(self, obs: Observation, why: str) -> Plan:
        """Nothing to fly to: hold the pose and be asked again at the next step (v4: the plan
        takes no time, so the next call comes one physics step, 10 ms, later, or after the
        charged planning time), or fall back or end (v1-v3)."""
        if not self.config.hover_when_no_goal:
            return self._fall_back(obs, why)
        here = np.asarray(obs.pose.position, dtype=np.float64)
        if self._previous and np.array_equal(self._previous[-1], here):
            self._previous.pop()  # `plan` recorded it; hovering is no step to go back to
        return Plan(np.array([[*here, obs.pose.yaw]]), info={"mode": "hover", "reason": why})

    def _fall_back(self, obs: Observation, why: str) -> Plan:
        """Classic's nearest frontier, whose own end condition ends the exploration. The cache
        holds only views the local trees passed, and a tree's branch counts only when its
        discounted value (lambda 0.75 /m) exceeds 1 m³: in a maze whose unknown part lies a few
        metres down a corridor, neither may see it (a MAZE run in the service ended at 108 s,
        29 % covered, with a frontier 4.7 m away). The local trees take over again from there."""
        if self._fallback is None:
            return Plan.finished(why)
        plan = frontier_fallback(self._fallback, obs, why=why)
        if plan.done:
            return Plan.finished(f"{why}, and {plan.info.get('reason', 'no frontier left')}")
        return plan


class AepV1(AepPlanner):
    """aep-v1, kept registered so that its stored results stay comparable and re-runnable."""

    config_model = AepV1Config
    config: AepV1Config


class Aep(AepPlanner):
    """aep-v2."""

    config_model = AepConfig
    config: AepConfig


class AepV3(AepPlanner):
    """aep-v3."""

    config_model = AepV3Config
    config: AepV3Config


class AepV4(AepPlanner):
    """aep-v4."""

    config_model = AepV4Config
    config: AepV4Config
