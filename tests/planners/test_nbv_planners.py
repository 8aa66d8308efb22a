"""Rapid, NBVP and AEP on maps made by hand: what each decides, and why."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planners.aep import AepConfig, AepPlanner
from planners.gain import GainEvaluator
from planners.nbv_tree import TreeSettings, _branch_sums, grow_tree
from planners.nbvp import Nbvp, NbvpConfig
from planners.registry import make, spec
from planners.surface_gaps import close_surface_gaps
from sim.camera import CameraConfig
from sim.geometry import Pose
from sim.interface import Observation, PlannerContext, PlanOutcome
from sim.occupancy import VoxelState
from sim.search_checks import plan_is_clear
from sim.vehicle import VehicleLimits
from tests.planners.conftest import stack_from_state

VOXEL = 0.1
SHAPE = (80, 40, 25)
SAFETY = 0.45
START = np.array([1.5, 2.0, 1.25])


def _corridor(known_until_x: float) -> np.ndarray:
    """A corridor along +x (walls at y = 0, 4 m; floor and ceiling), known up to x."""
    state = np.zeros(SHAPE, dtype=np.uint8)
    known = int(known_until_x / VOXEL)
    state[:known, :, :] = VoxelState.FREE
    state[:known, 0, :] = state[:known, -1, :] = VoxelState.OCCUPIED
    state[:known, :, 0] = state[:known, :, -1] = VoxelState.OCCUPIED
    state[0, :, :] = VoxelState.OCCUPIED
    return state


def _long_corridor() -> np.ndarray:
    """A closed corridor along +x, all known and free inside."""
    state = np.full(SHAPE, VoxelState.FREE, dtype=np.uint8)
    state[:, 0, :] = state[:, -1, :] = VoxelState.OCCUPIED
    state[:, :, 0] = state[:, :, -1] = VoxelState.OCCUPIED
    state[0, :, :] = state[-1, :, :] = VoxelState.OCCUPIED
    return state


def _context(seed: int = 0) -> PlannerContext:
    return PlannerContext(
        area="corridor", bounds_min=np.zeros(3), bounds_max=np.array(SHAPE) * VOXEL,
        start=Pose(START.copy(), 0.0), limits=VehicleLimits(), safety_radius_m=SAFETY,
        camera=CameraConfig(), rng=np.random.default_rng(seed),
    )


def _observe(state: np.ndarray, *, yaw: float = 0.0, velocity: np.ndarray | None = None,
             outcome: PlanOutcome = PlanOutcome.NONE, position: np.ndarray = START) -> Observation:
    view = stack_from_state(state, VOXEL, SAFETY).view()
    return Observation(0.0, Pose(position.copy(), yaw),
                       np.zeros(3) if velocity is None else velocity, view, outcome)


def _assert_flyable(obs: Observation, waypoints: np.ndarray) -> None:
    view = obs.map
    assert plan_is_clear(view.traversable, view.free, view.origin, VOXEL, obs.pose.position,
                         waypoints[:, :3]) == len(waypoints)


# -- Rapid --------------------------------------------------------------------------------------


def test_rapid_flies_on_toward_the_frontier_ahead() -> None:
    planner = make("rapid")
    planner.reset(_context())
    obs = _observe(_corridor(4.5), velocity=np.array([1.5, 0.0, 0.0]),
                   outcome=PlanOutcome.FLYING)
    plan = planner.plan(obs)
    assert plan.info["mode"] == "direct"
    assert plan.replan_s == pytest.approx(planner.config.replan_period_s)
    goal = plan.waypoints[0]
    assert goal[0] > START[0] + 1.0  # ahead, along the current velocity
    assert abs(goal[3]) < math.radians(30)
    _assert_flyable(obs, plan.waypoints)


def test_rapid_prefers_the_least_turn() -> None:
    """Frontiers ahead and to the left; flying left, it keeps going left."""
    state = _corridor(4.5)
    state[:, 30:, :] = VoxelState.UNKNOWN  # the corridor's left part is unknown too
    planner = make("rapid")
    planner.reset(_context())
    side = np.array([1.5, 1.0, 1.25])
    left = planner.plan(_observe(state, yaw=math.pi / 4, velocity=np.array([0.0, 1.2, 0.0]),
                                 outcome=PlanOutcome.FLYING, position=side))
    ahead = make("rapid")
    ahead.reset(_context())
    straight = ahead.plan(_observe(state, yaw=0.0, velocity=np.array([1.2, 0.0, 0.0]),
                                   outcome=PlanOutcome.FLYING))
    assert left.info["mode"] == straight.info["mode"] == "direct"
    assert left.info["angle_deg"] < 45 and straight.info["angle_deg"] < 45
    assert left.waypoints[0, 1] > side[1] + 0.9
    assert straight.waypoints[0, 0] > START[0] + 1.0


def test_rapid_keeps_flying_when_nothing_is_in_view_and_falls_back_at_rest() -> None:
    state = _corridor(4.5)
    planner = make("rapid")
    planner.reset(_context())
    # Looking back at the known end wall: no frontier in view.
    flying = planner.plan(_observe(state, yaw=math.pi, velocity=np.array([-0.5, 0.0, 0.0]),
                                   outcome=PlanOutcome.FLYING))
    assert flying.keep and flying.replan_s == planner.config.replan_period_s
    at_rest = planner.plan(_observe(state, yaw=math.pi, outcome=PlanOutcome.REACHED))
    assert at_rest.info["mode"] == "classic"
    assert at_rest.replan_s == planner.config.replan_period_s
    _assert_flyable(_observe(state, yaw=math.pi), at_rest.waypoints)


# -- NBVP ---------------------------------------------------------------------------------------


def test_nbvp_flies_the_first_edge_toward_the_unknown() -> None:
    planner = make("nbvp")
    planner.reset(_context())
    obs = _observe(_corridor(4.5))
    plan = planner.plan(obs)
    assert not plan.done and plan.info["mode"] == "local"
    assert len(plan.waypoints) == 1
    step = np.linalg.norm(plan.waypoints[0, :3] - START)
    assert 0 < step <= planner.config.extension_m + 1e-9
    assert plan.info["best_value"] > planner.config.zero_gain
    _assert_flyable(obs, plan.waypoints)


def test_nbvp_finishes_when_nothing_is_left_to_see() -> None:
    state = _corridor(8.0)  # everything known
    planner = make("nbvp", {"max_nodes": 40})
    planner.reset(_context())
    plan = planner.plan(_observe(state))
    assert plan.done


def test_nbvp_keeps_exploring_while_any_node_sees_unknown() -> None:
    """The original's rule: gain is found as soon as a branch beats the root, however little."""
    state = _corridor(8.0)
    state[30:33, 19:22, 11:14] = VoxelState.UNKNOWN  # a 0.027 m³ pocket ahead of the vehicle
    planner = make("nbvp")
    planner.reset(_context())
    obs = _observe(state)
    plan = planner.plan(obs)
    assert not plan.done, plan.info
    # Worth less than `wide_below_gain_m3`: a whole-area tree is grown too, and may win.
    assert plan.info["mode"] in ("local", "wide")
    assert 0.0 < plan.info["best_value"] < 0.1
    _assert_flyable(obs, plan.waypoints)


def test_nbvp_tree_samples_a_box_around_the_vehicle() -> None:
    """Every node lies in the sampling box around the root; every edge is at most one
    extension range long."""
    settings = NbvpConfig(sampling_radius_m=1.0, min_nodes=40, max_nodes=40).tree_settings()
    obs = _observe(_corridor(8.0))  # all known: no gain, so the tree grows to max_nodes
    grown = grow_tree(obs.map, GainEvaluator(CameraConfig(), 10.0, VOXEL), settings,
                      np.random.default_rng(3), START, 0.0, np.zeros(3),
                      np.array(SHAPE) * VOXEL)
    tree = grown.tree
    assert tree.size == 41 and not grown.gain_found
    assert np.all(np.abs(tree.positions - START) <= 1.0 + 1e-9)
    edges = np.linalg.norm(tree.positions[1:] - tree.positions[tree.parents[1:]], axis=1)
    assert np.all(edges <= settings.extension_m + 1e-9)


def test_nbvp_samples_the_whole_area_before_finishing() -> None:
    """Unknown beyond the gain range of every node of the box: the whole-area tree finds it."""
    state = _corridor(8.0)
    state[72:75, 19:22, 11:14] = VoxelState.UNKNOWN  # 5.7 m ahead, out of the box's reach
    planner = make("nbvp-v1", {"sampling_radius_m": 0.3, "max_nodes": 60})
    planner.reset(_context())
    obs = _observe(state)
    plan = planner.plan(obs)
    assert not plan.done, plan.info
    assert plan.info["mode"] == "wide"
    _assert_flyable(obs, plan.waypoints)


def test_nbvp_grows_the_whole_area_tree_when_the_local_gain_is_tiny() -> None:
    """A tiny pocket inside the box, a large unknown region beyond it: the whole-area tree's
    best branch is worth more than the local one's, and the vehicle follows it."""
    state = _corridor(8.0)
    state[20:22, 28:30, 11:13] = VoxelState.UNKNOWN  # 0.008 m³ beside the vehicle
    state[50:79, 1:39, 1:24] = VoxelState.UNKNOWN  # 2.9 x 3.8 x 2.3 m from x = 5 m
    # Nodes within 1 m of the vehicle see 2 m: up to x = 4.5 m, short of the large region.
    config = {"sampling_radius_m": 1.0, "gain_range_m": 2.0}
    local_only = make("nbvp-v1", {**config, "wide_below_gain_m3": None})
    local_only.reset(_context())
    obs = _observe(state)
    local = local_only.plan(obs)
    assert local.info["mode"] == "local"
    assert 0.0 < local.info["best_value"] < 0.1
    planner = make("nbvp-v1", config)
    planner.reset(_context())
    plan = planner.plan(obs)
    assert plan.info["mode"] == "wide", plan.info
    assert plan.info["local_value"] < 0.1 < plan.info["best_value"]
    assert plan.waypoints[0, 0] > START[0]  # toward the unknown region
    _assert_flyable(obs, plan.waypoints)


def test_aep_never_grows_the_whole_area_tree_beside_a_local_gain() -> None:
    """AEP finds local gain only above its `zero_gain`, so the fallback never applies."""
    config = AepConfig()
    assert config.wide_below_gain_m3 is None or config.wide_below_gain_m3 <= config.zero_gain


def test_branch_values_accumulate_discounted_gains() -> None:
    obs = _observe(_corridor(4.5))
    settings = TreeSettings(extension_m=1.0, sampling_radius_m=None, min_nodes=30, max_nodes=30,
                            max_failures_per_node=1000, degressive_coeff=0.5, zero_gain=1.0,
                            rewire_radius_m=1.2, yaw="best")
    gains = GainEvaluator(CameraConfig(), 10.0, VOXEL)
    grown = grow_tree(obs.map, gains, settings, np.random.default_rng(4), START, 0.0,
                      np.zeros(3), np.array(SHAPE) * VOXEL)
    tree = grown.tree
    assert tree.size == 31
    for n in range(tree.size):
        branch = tree.branch(n)
        expected = np.sum(tree.gains[branch] * np.exp(-0.5 * tree.costs[branch]))
        assert tree.values[n] == pytest.approx(expected)
    assert grown.best == int(np.argmax(tree.values[1:])) + 1


def _pointer_jumping(own: np.ndarray, parents: np.ndarray) -> np.ndarray:
    """The reference: the rounds of pointer jumping in NumPy, as the branch values were summed
    before they were compiled."""
    acc, up = own.copy(), parents.copy()
    while np.any(up >= 0):
        has = up >= 0
        new_acc = acc.copy()
        new_acc[has] += acc[up[has]]
        new_up = up.copy()
        new_up[has] = up[up[has]]
        acc, up = new_acc, new_up
    return acc


@pytest.mark.parametrize("seed", range(4))
def test_branch_sums_round_as_the_numpy_rounds_do(seed: int) -> None:
    """The same sums to the bit, for trees whose ids come in any order (RRT* re-hangs nodes
    under newer ones) and gains over six orders of magnitude."""
    rng = np.random.default_rng(seed)
    for size in (1, 2, 3, 17, 64, 300):
        order = rng.permutation(size)
        parents = np.full(size, -1, dtype=np.int64)
        for t in range(1, size):
            parents[order[t]] = order[rng.integers(0, t)]
        own = rng.random(size) * rng.choice([1e-3, 1.0, 1e3], size)
        assert np.array_equal(_branch_sums(own, parents), _pointer_jumping(own, parents))


# -- AEP ----------------------------------------------------------------------------------------


def test_aep_goes_back_to_a_cached_view_when_the_local_gain_runs_out() -> None:
    planner = make("aep-v3")
    assert isinstance(planner, AepPlanner)
    planner.reset(_context())
    state = _corridor(4.5)
    first = planner.plan(_observe(state))
    assert first.info["mode"] == "local"
    assert len(planner._cache) > 0
    # Far down a long known corridor, out of the local tree's reach, the only unknown is back
    # where the cache remembers it.
    long = _long_corridor()
    long[3:6, 5:35, 3:22] = VoxelState.UNKNOWN  # some unknown left behind the start
    far = np.array([7.5, 2.0, 1.25])
    plan = planner.plan(_observe(long, position=far, outcome=PlanOutcome.REACHED))
    assert plan.info["mode"] == "global", plan.info
    assert len(plan.waypoints) >= 1
    # Back toward the unknown, arriving with the camera turned to it.
    assert plan.waypoints[-1, 0] < far[0] - 1.0
    assert math.cos(plan.waypoints[-1, 3]) < 0.0
    _assert_flyable(_observe(long, position=far), plan.waypoints)


def test_aep_finishes_with_nothing_cached_and_nothing_to_see() -> None:
    planner = make("aep-v3")
    planner.reset(_context())
    plan = planner.plan(_observe(_corridor(8.0)))
    assert plan.done


def test_aep_flies_to_the_nearest_frontier_when_its_cache_runs_dry() -> None:
    """Nothing cached and no branch worth `zero_gain` (the unknown lies beyond the trees'
    reach): Classic's nearest frontier takes over instead of ending the exploration."""
    state = _corridor(8.0)
    state[72:75, 19:22, 11:14] = VoxelState.UNKNOWN  # 5.7 m ahead, out of the box's reach
    planner = make("aep-v3", {"sampling_radius_m": 0.3})
    assert isinstance(planner, AepPlanner)
    planner.reset(_context())
    obs = _observe(state)
    plan = planner.plan(obs)
    assert not plan.done, plan.info
    assert plan.info["mode"] == "classic" and plan.info["why"] == "no cached node left"
    # Toward the unknown block at x = 7.2-7.5 m, ending where the camera sees it.
    assert plan.waypoints[-1, 0] > START[0] + 1.5
    assert math.cos(plan.waypoints[-1, 3]) > 0.5
    _assert_flyable(obs, plan.waypoints)
    # aep-v1, kept for its stored results, ends there.
    first = make("aep-v1", {"sampling_radius_m": 0.3})
    first.reset(_context())
    assert first.plan(obs).done


# -- aep-v4: the global step of the public code the FLYBO authors ran --------------------------


def _aep_v4(**settings: object) -> AepPlanner:
    planner = make("aep-v4", settings)
    assert isinstance(planner, AepPlanner)
    planner.reset(_context())
    return planner


def test_aep_v4_is_the_newest_aep_and_keeps_the_published_thresholds() -> None:
    assert spec("aep").id == "aep-v4"
    config = make("aep-v4").config
    assert config.goal_gain_m3 == 16.0 and config.fallback is None
    assert config.hover_when_no_goal
    assert (config.reevaluate_period_s, config.reevaluate_range_m,
            config.reevaluate_above_m3) == (5.0, 10.0, 2.0)
    # The earlier versions keep their own global step.
    for old in ("aep-v1", "aep-v2", "aep-v3"):
        assert make(old).config.goal_gain_m3 is None


def test_aep_v4_flies_to_the_nearest_goal_not_the_most_valuable() -> None:
    """Two cached nodes above 16 m³: the nearer one by path is flown to, though the farther
    one's cached gain is ten times larger (rrtplanner's least-cost goal)."""
    planner = _aep_v4()
    near, far = np.array([3.5, 2.0, 1.25]), np.array([6.5, 2.0, 1.25])
    planner._cache.insert(near, 20.0, 0.0)
    planner._cache.insert(far, 200.0, 0.0)
    planner._reevaluated_at = 0.0  # not due: the cached gains stand
    obs = _observe(_long_corridor(), outcome=PlanOutcome.REACHED)
    plan = planner.plan(obs)
    assert plan.info["mode"] == "global", plan.info
    assert plan.info["goals"] == 2
    np.testing.assert_allclose(plan.waypoints[-1, :3], near, atol=VOXEL)
    _assert_flyable(obs, plan.waypoints)


def test_aep_v4_refreshes_only_the_gains_near_the_vehicle_when_due() -> None:
    """pig.py's timer: every 5 s, cached gains above 2 m³ within 10 m (per axis) are cast
    again on the map; farther nodes keep the gain they were cached with."""
    planner = _aep_v4(reevaluate_range_m=4.0)
    near = planner._cache.insert(np.array([3.5, 2.0, 1.25]), 50.0, 0.0)
    small = planner._cache.insert(np.array([4.5, 2.0, 1.25]), 1.5, 0.0)
    far = planner._cache.insert(np.array([7.0, 2.0, 1.25]), 60.0, 0.0)
    state = _long_corridor()
    planner._reevaluated_at = -10.0
    plan = planner.plan(Observation(3.0, Pose(START.copy(), 0.0), np.zeros(3),
                                    stack_from_state(state, VOXEL, SAFETY).view(),
                                    PlanOutcome.REACHED))
    # Everything round the near node is known: its gain is gone; the small one was not cast
    # again; the far one keeps its stale 60 m³ and is the goal.
    assert planner._cache.value(near) == pytest.approx(0.0)
    assert planner._cache.value(small) == pytest.approx(1.5)
    assert planner._cache.value(far) == pytest.approx(60.0)
    assert planner._reevaluated_at == 3.0
    assert plan.info["mode"] == "global" and plan.info["goals"] == 1
    np.testing.assert_allclose(plan.waypoints[-1, :3], [7.0, 2.0, 1.25], atol=VOXEL)
    # Asked again within 5 s, nothing is cast again.
    planner._cache.update(near, 50.0)
    planner.plan(Observation(6.0, Pose(START.copy(), 0.0), np.zeros(3),
                             stack_from_state(state, VOXEL, SAFETY).view(),
                             PlanOutcome.REACHED))
    assert planner._cache.value(near) == pytest.approx(50.0)


def test_aep_v4_drops_an_unreachable_goal_and_flies_to_the_next() -> None:
    """The nearer goal lies inside a solid block no path reaches: it leaves the cache and
    the farther, reachable one is flown to; with none reachable, the vehicle hovers."""
    state = _long_corridor()
    state[38:45, 15:26, 8:18] = VoxelState.OCCUPIED  # a block round (4.15, 2.05, 1.25)
    planner = _aep_v4()
    walled = planner._cache.insert(np.array([4.15, 2.05, 1.25]), 40.0, 0.0)
    open_ = planner._cache.insert(np.array([6.5, 2.0, 0.6]), 40.0, 0.0)
    planner._reevaluated_at = 0.0  # not due
    obs = _observe(state, outcome=PlanOutcome.REACHED)
    plan = planner.plan(obs)
    assert plan.info["mode"] == "global", plan.info
    np.testing.assert_allclose(plan.waypoints[-1, :3], [6.5, 2.0, 0.6], atol=VOXEL)
    assert walled not in planner._cache.ids() and open_ in planner._cache.ids()
    planner._cache.remove(open_)
    planner._cache.insert(np.array([4.15, 2.05, 1.25]), 40.0, 0.0)
    plan = planner.plan(obs)
    assert plan.info["mode"] == "hover"
    assert plan.info["reason"] == "no node gaining more than 16 m³ is reachable"


def test_aep_v4_turns_on_the_spot_to_a_goal_it_stands_on() -> None:
    planner = _aep_v4()
    planner._cache.insert(START + np.array([0.2, 0.0, 0.0]), 30.0, math.pi)
    planner._reevaluated_at = 0.0  # not due
    plan = planner.plan(_observe(_long_corridor(), outcome=PlanOutcome.REACHED))
    assert plan.info["mode"] == "global", plan.info
    np.testing.assert_allclose(plan.waypoints, [[*START, math.pi]])


def test_aep_v4_refreshes_the_gains_near_it_while_exploring_locally() -> None:
    """pig.py's timer runs whatever the planner does: a call that finds local gain refreshes
    the cache near the vehicle too, once due."""
    planner = _aep_v4()
    stale = planner._cache.insert(np.array([2.5, 2.0, 1.25]), 80.0, 0.0)
    planner._reevaluated_at = -10.0
    obs = _observe(_corridor(4.5))
    plan = planner.plan(obs)
    assert plan.info["mode"] == "local", plan.info
    assert planner._reevaluated_at == obs.time
    assert planner._cache.value(stale) < 80.0


def test_aep_v4_hovers_and_plans_again_when_no_goal_is_left() -> None:
    """Nothing cached and nothing to see: the FLYBO authors' exploration loop asks the planner
    again rather than ending, so the vehicle holds its pose; a goal cached meanwhile is flown
    to at the next call."""
    planner = _aep_v4()
    obs = _observe(_long_corridor(), yaw=0.3, outcome=PlanOutcome.REACHED)
    plan = planner.plan(obs)
    assert not plan.done
    assert plan.info["mode"] == "hover", plan.info
    np.testing.assert_allclose(plan.waypoints, [[*START, 0.3]])
    planner._cache.insert(np.array([5.5, 2.0, 1.25]), 30.0, 0.0)
    planner._reevaluated_at = obs.time  # not due
    assert planner.plan(obs).info["mode"] == "global"


def test_nbvp_v2_is_the_published_method() -> None:
    """nbvp-v2 (what `nbvp` names) turns nbvp-v1's three additions off: one tree sampled in
    the whole area, no second tree, gains cast through the map as it is."""
    assert spec("nbvp").id == "nbvp-v2"
    v1, v2 = make("nbvp-v1").config.model_dump(), make("nbvp-v2").config.model_dump()
    assert {k for k in v1 if v1[k] != v2[k]} == {
        "sampling_radius_m", "wide_below_gain_m3", "surface_gap_m"}
    assert v2["sampling_radius_m"] is None and v2["wide_below_gain_m3"] is None
    assert v2["surface_gap_m"] is None


def _holed_wall() -> np.ndarray:
    """All known but a thick wall at y < 0.3 m whose unknown interior shows through a hole in
    its occupied layer, 1.8 m to the vehicle's right (as grazing rays leave walls on MAZE)."""
    state = _corridor(8.0)
    state[:, 0:2, 1:-1] = VoxelState.UNKNOWN  # the wall's interior, never observable
    state[:, 2, :] = VoxelState.OCCUPIED  # its surface layer...
    state[18:21, 2, 10:15] = VoxelState.FREE  # ...with a hole swept free
    return state


def test_nbvp_closes_holes_in_walls_before_counting_the_unknown_behind_them() -> None:
    """The wall's interior, seen through a hole in its occupied layer, keeps a gain that no
    flight can reduce: the original rule never finishes there; with narrow gaps in occupied
    surfaces closed for the gain, nothing is left to see and NBVP ends."""
    state = _holed_wall()
    right = -math.pi / 2
    obs = _observe(state, yaw=right, outcome=PlanOutcome.REACHED)
    planner = make("nbvp-v1", {"max_nodes": 40})
    assert isinstance(planner, Nbvp)
    # nbvp-v2, the published method, casts through the hole and never finishes here.
    published = make("nbvp-v2", {"max_nodes": 40})
    published.reset(_context())
    assert not published.plan(obs).done
    planner.reset(_context())
    gains = planner.gain_evaluator(VOXEL)
    assert gains.gain(obs.map, START, right) > 0.0
    assert planner.plan(obs).done
    closed = planner._gain_state
    assert closed is not None
    assert gains.at_yaw(gains.columns(obs.map, START, closed), right) == 0.0
    original = make("nbvp-v1", {"max_nodes": 40, "surface_gap_m": None})
    original.reset(_context())
    plan = original.plan(obs)
    assert not plan.done and plan.info["best_value"] > 0.0


def test_closing_surface_gaps_keeps_openings_the_vehicle_can_use() -> None:
    """A 0.3 m gap in a wall closes; a 0.4 m one, the corridor and unknown space do not."""
    state = _corridor(8.0)
    state[:, 25:, :] = VoxelState.UNKNOWN
    state[:, 20, :] = VoxelState.OCCUPIED  # a wall along x at y = 2 m...
    state[10:13, 20, 5:20] = VoxelState.FREE  # ...with a 0.3 m gap
    state[30:34, 20, 5:20] = VoxelState.FREE  # and a 0.4 m one
    closed = close_surface_gaps(state, 3)
    assert np.all(closed[10:13, 20, 5:20] == VoxelState.OCCUPIED)
    assert np.all(closed[30:34, 20, 5:20] == VoxelState.FREE)
    changed = closed != state
    assert not np.any(changed[:, 21:, :]) and not np.any(changed[:, 1:20, 1:-1])
