"""ESM: efficient sampling-based online informative path planning (Schmid et al., RA-L 2020).

One tree of straight trajectory segments, rooted at the vehicle, persists for the whole
exploration and grows at every planning call (the paper expands it continuously while flying):
as many samples as the root lacks nodes within `local_radius_m` (of `local_count`) are drawn on
that sphere, the rest uniformly in the area's box (`global_sampling`, as the paper, or in the
map's traversable space); each is steered at most `extension_m` from the first of its
`steer_candidates` nearest nodes that gives a segment, kept only in traversable space and at
least `density_radius_m` from every node, and gets the gain of its view at its best yaw. It is
inserted RRT*-style (`planners.segment_tree`): the parent that maximises its value, then nearby
nodes re-hung under it where that raises their value. Every segment is checked against
`traversable` again at each call; blocked ones are reconnected or dropped with their subtrees.

A node's value is the best gain per second of flight of any branch through it (the paper's
normalized gain: sum of gains / sum of segment flight times from the root, maximised over the
subtree). The vehicle flies the root's child of highest value; that child becomes the root, the
segment just flown is reversed so that the old root and its other branches hang from the new root
(the paper re-hangs them, reinserting the old root where needed), and the old root's other
children are re-hung under better parents where that raises their value.

Gains are recomputed lazily: each stores the simulated time it was computed; since gains only
shrink as the map fills in, a stale gain bounds the current one from above, so the best branch is
found best-first, recomputing only the stale nodes on the branch that currently looks best until
the best branch is all fresh.

When no branch is worth `min_value`, the vehicle flies back along the stack of positions it
planned from (a straight line, or an A* path when that is blocked) while the tree keeps growing;
exploration ends when the stack is empty and still nothing is worth flying to.

ESM-IPP scores a view by the unknown volume it would see (`planners.gain`); ESM-Recon by its
reconstruction gain (`planners.recon_gain`).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from planners.api import Observation, Plan, Planner, PlannerContext
from planners.astar import PathCache
from planners.esm_config import EsmConfig, EsmReconConfig
from planners.esm_screen import SteerRule, skip_failing_tries
from planners.gain import GainEvaluator
from planners.lines import reachable_lengths, segment_clear_world, segments_clear
from planners.recon_gain import ReconGainEvaluator
from planners.rrt import steer
from planners.segment_tree import (
    BoolArray,
    FlightTime,
    SegmentTree,
    insert,
    prune_blocked,
    rewire,
)
from planners.surface_gaps import StateGrid, close_surface_gaps
from planners.waypoints import grid_path, path_waypoints, tree_root
from sim.map_view import MapView

FloatArray = npt.NDArray[np.float64]


class Esm(Planner):
    config_model = EsmConfig
    config: EsmConfig
    # Skip the tries `_steer` surely fails on in compiled code (`planners.esm_screen`): the
    # same tree, faster; off only to check that.
    screen_tries: bool = True

    def reset(self, ctx: PlannerContext) -> None:
        super().reset(ctx)
        lim = ctx.limits
        self._flight = FlightTime(lim.v_max, lim.a_max, lim.yaw_rate_max, lim.yaw_acc_max)
        self._gains: GainEvaluator | None = None
        self._tree: SegmentTree | None = None
        self._pending = -1  # the node being flown to
        self._stack: list[FloatArray] = []  # positions planned from, for back-tracking
        self._paths = PathCache()
        self._view: MapView | None = None
        self._gain_state: StateGrid | None = None  # this call's states the gain is cast through
        self._refreshed = 0

    # -- services --------------------------------------------------------------------------
    def gain_evaluator(self, voxel_size: float) -> GainEvaluator:
        if self._gains is None:
            cfg, camera = self.config, self.context.camera
            if cfg.gain == "reconstruction":
                self._gains = ReconGainEvaluator(
                    camera, cfg.ray_step_deg, voxel_size, cfg.gain_range_m,
                    unknown_weight=cfg.unknown_weight, surface_weight=cfg.surface_weight,
                    direction_bonus=cfg.direction_bonus, new_weight=cfg.new_weight,
                    min_impact=cfg.min_impact, min_directions=cfg.min_directions)
            else:
                self._gains = GainEvaluator(camera, cfg.ray_step_deg, voxel_size,
                                            cfg.gain_range_m)
        return self._gains

    def _clear(self, a: FloatArray, b: FloatArray) -> BoolArray:
        view = self._current_view()
        return segments_clear(view, view.traversable, a, b)

    def _current_view(self) -> MapView:
        if self._view is None:
            raise RuntimeError("no map view")
        return self._view

    @property
    def tree(self) -> SegmentTree | None:
        return self._tree

    # -- planning --------------------------------------------------------------------------
    def plan(self, obs: Observation) -> Plan:
        self._view = obs.map
        self._gain_state = None
        root, snapped = tree_root(obs.map, obs.pose.position)
        if root is None:
            return Plan.finished("the vehicle is not in traversable space")
        tree = self._attach(root, obs.pose.yaw)
        dropped, _ = prune_blocked(tree, self._clear, self._flight, self.config.rewire_radius_m,
                                   self.config.neighbours)
        tree.gains[tree.root] = 0.0  # the vehicle is there: nothing left to gain
        tree.stamps[tree.root] = obs.time
        self._refreshed = 0
        added, child, value = self._grow_and_select(tree, obs)
        info: dict[str, float | int | str] = {
            "nodes": int(tree.size), "added": added, "dropped": dropped,
            "refreshed": self._refreshed, "value": value,
        }
        if child < 0 or value <= self.config.min_value:
            return self._back_track(obs, info)
        self._stack.append(tree.positions[tree.root].copy())
        limit = self.config.backtrack_stack
        if limit is not None and len(self._stack) > limit:
            del self._stack[: len(self._stack) - limit]
        self._pending = child
        waypoints = np.array([[*tree.positions[child], tree.yaws[child]]])
        if snapped:
            waypoints = np.vstack([[*tree.positions[tree.root], tree.yaws[child]], waypoints])
        info.update(mode="tree", gain=float(tree.gains[child]))
        return Plan(waypoints, info=info)


    def _attach(self, root: FloatArray, yaw: float) -> SegmentTree:
        """The tree rooted at `root`: re-rooted at the segment just flown when the vehicle
        reached it, else hung from a new root node at the vehicle."""
        cfg, tree = self.config, self._tree
        pending, self._pending = self._pending, -1
        if tree is None:
            self._tree = SegmentTree(root, yaw)
            return self._tree
        if pending >= 0 and np.linalg.norm(tree.positions[pending] - root) <= \
                cfg.reach_tolerance_m:
            old = tree.root
            tree.reroot(pending, self._flight)
            tree.positions[pending] = root
            tree.yaws[pending] = yaw
            for child in tree.children(old):
                rewire(tree, int(child), self._clear, self._flight, cfg.rewire_radius_m,
                       cfg.neighbours)
            if len(tree.children(old)) == 0:
                keep = np.ones(tree.size, dtype=bool)
                keep[old] = False
                tree.keep(keep)
            return tree
        # Back-tracked or stopped short: hang the tree from the vehicle through the nearest
        # node with a clear segment, reversing the way from it to the old root. Any distance
        # will do (our choice; a segment's flight time prices its length): limited to
        # `rewire_radius_m`, a back-tracked vehicle often found no node and the whole tree,
        # with the branches toward unexplored space, was thrown away.
        order = np.argsort(np.sum((tree.positions - root) ** 2, axis=1), kind="stable")
        clear = self._clear(np.repeat(root[None], len(order), axis=0), tree.positions[order])
        near = order[clear]
        if len(near) == 0:
            self._tree = SegmentTree(root, yaw)
            return self._tree
        link = int(near[0])
        tree.reroot(link, self._flight)
        new_root = tree.add(root, -1, yaw, 0.0)
        cost = float(self._flight(root, yaw, tree.positions[link], tree.yaws[link])[0])
        tree.set_parent(link, new_root, cost)
        tree.root = new_root
        return tree

    def _evaluate(self, view: MapView, position: FloatArray) -> tuple[float, float]:
        """(yaw, gain) of the best view at `position`."""
        gains = self.gain_evaluator(view.voxel_size)
        best = gains.best_view(view, position, self._cast_state(view, gains))
        return best.yaw, best.gain

    def _cast_state(self, view: MapView, gains: GainEvaluator) -> StateGrid | None:
        """The map states the gain is cast through in this call: surface gaps up to
        `surface_gap_m` closed, made once per call on first use (None: the map's own)."""
        gap = self.config.surface_gap_m
        if gap is None:
            return None
        if self._gain_state is None:
            self._gain_state = close_surface_gaps(view.state, round(gap / view.voxel_size),
                                                  gains.gap_fill)
        return self._gain_state

    def _grow_and_select(self, tree: SegmentTree, obs: Observation) -> tuple[int, int, float]:
        """In a call made at rest: grow the tree (here always, `_expand`), then choose the
        root's child to fly (`select`). Returns (segments added, child, value)."""
        added = self._expand(tree, obs)
        child, value = self.select(tree, obs.map, obs.time)
        return added, child, value

    def _sampling_centre(self, tree: SegmentTree) -> FloatArray:
        """(3,) the point the semilocal samples are drawn round: the root."""
        centre: FloatArray = tree.positions[tree.root]
        return centre

    def _expand(self, tree: SegmentTree, obs: Observation) -> int:
        """Grow the tree by up to `new_per_call` segments; returns how many were added."""
        cfg, ctx, view = self.config, self.context, obs.map
        rng = ctx.rng
        root = self._sampling_centre(tree)
        d_root = np.linalg.norm(tree.positions - root, axis=1)
        local_missing = cfg.local_count - (int(np.count_nonzero(d_root <= cfg.local_radius_m))
                                           - 1)
        added = 0
        tries = 0
        traversable: npt.NDArray[np.intp] | None = None  # flat ids, drawn from on first use
        screen = self.screen_tries and cfg.global_sampling == "box"
        while tries < cfg.tries_per_call and added < cfg.new_per_call:
            if screen:
                # The tries `_steer` surely fails on, skipped as if made (`planners.esm_screen`).
                skipped = skip_failing_tries(rng, tree.positions, view, self._steer_rule(), root,
                                             cfg.local_radius_m, local_missing, ctx.bounds_min,
                                             ctx.bounds_max, cfg.tries_per_call - tries)
                tries += skipped
                local_missing -= min(skipped, max(local_missing, 0))
                if tries >= cfg.tries_per_call:
                    break
            tries += 1
            if local_missing > 0:
                # Semilocal sampling: a point on the sphere of `local_radius_m` round the root,
                # at most as many as local nodes are missing, kept or not (as the paper's
                # sampler counts them), so that a root in a corridor too narrow to hold
                # `local_count` nodes does not starve the global samples.
                local_missing -= 1
                direction = rng.normal(size=3)
                direction /= max(float(np.linalg.norm(direction)), 1e-12)
                sample = root + cfg.local_radius_m * direction
            elif cfg.global_sampling == "traversable":
                if traversable is None:
                    traversable = np.flatnonzero(view.traversable)
                    if len(traversable) == 0:
                        break
                voxel = np.array(np.unravel_index(int(rng.choice(traversable)), view.shape))
                sample = view.index_to_world(voxel[None])[0] + \
                    rng.uniform(-0.5, 0.5, 3) * view.voxel_size
            else:
                sample = rng.uniform(ctx.bounds_min, ctx.bounds_max)
            new = self._steer(tree, view, sample)
            if new is None:
                continue
            yaw, gain = self._evaluate(view, new)
            node = insert(tree, new, yaw, gain, obs.time, self._clear, self._flight,
                          cfg.rewire_radius_m, cfg.neighbours)
            if node < 0:
                continue
            added += 1
        return added

    def _steer_rule(self) -> SteerRule:
        """What `_steer` and `_crop` test, for the screen of failing tries."""
        cfg = self.config
        return SteerRule(candidates=cfg.steer_candidates, extension_m=cfg.extension_m,
                         crop_margin_m=cfg.crop_margin_m, crop_min_m=cfg.crop_min_m,
                         min_segment_m=0.0, density_radius_m=cfg.density_radius_m)

    def _steer(self, tree: SegmentTree, view: MapView, sample: FloatArray) -> FloatArray | None:
        """A new node position toward `sample` from the first of its `steer_candidates`
        nearest nodes that gives one (`_crop`) at least `density_radius_m` from every node."""
        cfg = self.config
        d2 = np.sum((tree.positions - sample) ** 2, axis=1)
        count = min(cfg.steer_candidates, tree.size)
        nearest = np.argpartition(d2, count - 1)[:count] if count < tree.size else \
            np.arange(tree.size)
        for node in nearest[np.argsort(d2[nearest], kind="stable")]:
            new = self._crop(view, tree.positions[node], sample)
            if new is None:
                continue
            if float(np.min(np.sum((tree.positions - new) ** 2, axis=1))) >= \
                    cfg.density_radius_m ** 2:
                return new
        return None

    def _crop(self, view: MapView, start: FloatArray, sample: FloatArray) -> FloatArray | None:
        """The point `extension_m` from `start` toward `sample`, or, where the way is blocked
        before, `crop_margin_m` short of the block (None if that leaves less than
        `crop_min_m`): the paper crops its segments the same way."""
        cfg = self.config
        goal = steer(start, sample, cfg.extension_m)
        full = float(np.linalg.norm(goal - start))
        if full < 1e-6:
            return None
        reach = float(reachable_lengths(view, start, goal[None])[0])
        length = full if reach >= full - 1e-9 else reach - cfg.crop_margin_m
        if length < min(cfg.crop_min_m, full):
            return None
        point: FloatArray = start + (goal - start) * (length / full)
        voxel = view.world_to_index(point[None])[0]
        if not (np.all(view.in_bounds(voxel[None]))
                and view.traversable[voxel[0], voxel[1], voxel[2]]):
            return None
        return point

    def refresh(self, tree: SegmentTree, view: MapView, node: int, now: float) -> None:
        """Recompute the gain and best yaw of `node` on the current map."""
        yaw, gain = self._evaluate(view, tree.positions[node])
        self._refreshed += 1
        tree.gains[node] = gain
        tree.stamps[node] = now
        if yaw != tree.yaws[node]:
            tree.yaws[node] = yaw
            # The yaw changes the flight time of its own segment and of those leaving it.
            parent = int(tree.parents[node])
            if parent >= 0:
                tree.costs[node] = float(self._flight(tree.positions[parent], tree.yaws[parent],
                                                      tree.positions[node], yaw)[0])
            kids = tree.children(node)
            if len(kids):
                tree.costs[kids] = self._flight(
                    np.repeat(tree.positions[node][None], len(kids), axis=0), yaw,
                    tree.positions[kids], tree.yaws[kids])

    def select(self, tree: SegmentTree, view: MapView, now: float) -> tuple[int, float]:
        """The root's child leading to the best branch, and its value, recomputing stale
        gains best-first (stale gains are upper bounds); (-1, 0) for a lone root."""
        if tree.size < 2:
            return -1, 0.0
        refreshable = self._refreshable(tree)
        while True:
            g, c, _ = tree.accumulate()
            ratio = np.where(c > 0.0, g / np.maximum(c, 1e-12), 0.0)
            ratio[tree.root] = -math.inf
            end = int(np.argmax(ratio))
            branch = tree.path(end)[1:]
            stale = branch[tree.stamps[branch] < now]
            if refreshable is not None:
                stale = stale[refreshable[stale]]
            if len(stale) == 0:
                return int(branch[0]), float(ratio[end])
            for node in stale:
                self.refresh(tree, view, int(node), now)

    def _refreshable(self, tree: SegmentTree) -> npt.NDArray[np.bool_] | None:
        """(N,) which nodes' stale gains `select` recomputes; None: every node's."""
        return None

    def _back_track(self, obs: Observation, info: dict[str, float | int | str]) -> Plan:
        """Fly back to the last position on the stack that can be reached."""
        here = np.asarray(obs.pose.position, dtype=np.float64)
        while self._stack:
            target = self._stack.pop()
            if np.linalg.norm(target - here) < self.config.reach_tolerance_m:
                continue
            waypoints = self._way_to(obs, target)
            if waypoints is not None:
                info.update(mode="back", stack=len(self._stack))
                return Plan(waypoints, info=info)
        plan = Plan.finished("no branch worth flying and nothing left to go back to")
        plan.info.update(info)
        return plan

    def _way_to(self, obs: Observation, target: FloatArray) -> FloatArray | None:
        """(N, 4) waypoints to `target`: straight if clear, else a shortest grid path."""
        view = obs.map
        here = np.asarray(obs.pose.position, dtype=np.float64)
        yaw = float(obs.pose.yaw)
        if segment_clear_world(view, view.traversable, here, target):
            heading = target - here
            if np.linalg.norm(heading[:2]) > 1e-6:
                yaw = float(np.arctan2(heading[1], heading[0]))
            return np.array([[*target, yaw]])
        found = grid_path(view, self._paths, here, target)
        if found is None:
            return None
        path, goal = found
        look = view.index_to_world(goal[None])[0] + 2.0 * (target - here)
        waypoints: FloatArray = path_waypoints(view, path, obs.pose.position, look)
        return waypoints


class EsmV1(Esm):
    """esm-ipp-v1, kept registered so that its stored results stay comparable and re-runnable;
    later versions share `Esm` with it, never this class."""


class EsmRecon(Esm):
    """ESM-Recon: `Esm` with the reconstruction gain."""

    config_model = EsmReconConfig
