"""Every registered planner: one short exact flight through the MAZE, and one plan on a map
made by hand."""

from __future__ import annotations

import itertools
import json
import math

import numpy as np
import pytest

from planners.registry import PlannerSpec, make, planner_ids, spec, specs
from sim.camera import CameraConfig
from sim.geometry import Pose
from sim.interface import Observation, Plan, PlannerContext, PlanOutcome
from sim.map_view import MappingStack
from sim.result import EpisodeResult, RunStatus
from sim.vehicle import VehicleLimits
from tests.sim.episode_fingerprints import SECONDS, STORE, fingerprint, run_flight

# The hand-made situation: a 4 x 4 x 2.5 m grid with a carved free ball around its centre.
BOUNDS_MIN = np.zeros(3)
BOUNDS_MAX = np.array([4.0, 4.0, 2.5])
VOXEL = 0.1
SHAPE = (40, 40, 25)
SAFETY_RADIUS = 0.45
CENTRE = np.array([2.0, 2.0, 1.25])
BALL_RADIUS = 1.5


@pytest.fixture(scope="module", params=planner_ids())
def exact_flights(request: pytest.FixtureRequest) -> tuple[str, EpisodeResult, EpisodeResult]:
    """Two short flights of one planner through the MAZE in one process, same seed, planning time
    not charged (the exact preset): the flight whose fingerprint is stored."""
    planner_id: str = request.param
    runs = [run_flight(planner_id) for _ in range(2)]
    return planner_id, runs[0], runs[1]


@pytest.mark.slow
def test_short_exact_flight_in_the_maze(
    exact_flights: tuple[str, EpisodeResult, EpisodeResult],
) -> None:
    planner_id, result, _ = exact_flights
    assert result.status is RunStatus.SUCCEEDED, result.reason
    assert result.collisions == 0
    assert result.iterations >= 1
    assert result.planner == planner_id
    assert result.area == "maze"

    times, volume = result.volume_times, result.volume_m3
    # One sample per simulated second, t = 0 .. SECONDS, even after an early finish.
    samples = round(SECONDS) + 1
    assert len(times) == samples
    np.testing.assert_allclose(times, np.arange(samples, dtype=np.float64), atol=1e-6)
    assert volume.shape == times.shape
    assert np.all(np.isfinite(volume))
    # The known-voxel count never decreases, so neither does the explored volume.
    assert np.all(np.diff(volume) >= 0.0)
    # Exploring: well beyond what the start-up turn alone reveals.
    assert result.explored_volume_m3 > 1.3 * volume[8]
    assert volume[-1] == pytest.approx(result.explored_volume_m3)

    planning = result.planning_times_ms
    assert len(planning) == result.iterations
    assert np.all(np.isfinite(planning))
    assert np.all(planning >= 0.0)


@pytest.mark.slow
def test_flight_matches_its_fingerprint(
    exact_flights: tuple[str, EpisodeResult, EpisodeResult],
) -> None:
    planner_id, result, _ = exact_flights
    stored: dict[str, str] = json.loads(STORE.read_text())
    assert fingerprint(result.to_json()) == stored[planner_id], (
        f"{planner_id} on MAZE (exact preset) no longer flies as its stored fingerprint says")


@pytest.mark.slow
def test_same_seed_flies_the_same_flight(
    exact_flights: tuple[str, EpisodeResult, EpisodeResult],
) -> None:
    _, first, second = exact_flights
    np.testing.assert_array_equal(first.volume_m3, second.volume_m3)
    assert first.path_length_m == second.path_length_m
    assert first.iterations == second.iterations


def _carved_stack() -> MappingStack:
    """A map where only a ball of radius `BALL_RADIUS` around `CENTRE` is known (free)."""
    stack = MappingStack(BOUNDS_MIN, SHAPE, VOXEL, SAFETY_RADIUS)
    n = 6000
    k = np.arange(n) + 0.5
    phi = np.arccos(1.0 - 2.0 * k / n)
    theta = np.pi * (1.0 + 5**0.5) * k
    dirs = np.stack(
        [np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], axis=1
    )
    stack.occupancy.integrate(CENTRE, CENTRE + BALL_RADIUS * dirs, np.zeros(n, dtype=bool))
    return stack


def _context(seed: int = 0) -> PlannerContext:
    return PlannerContext(
        area="handmade",
        bounds_min=BOUNDS_MIN.copy(),
        bounds_max=BOUNDS_MAX.copy(),
        start=Pose(CENTRE.copy(), 0.0),
        limits=VehicleLimits(),
        safety_radius_m=SAFETY_RADIUS,
        camera=CameraConfig(),
        rng=np.random.default_rng(seed),
    )


def test_handmade_situation_is_what_the_planners_get() -> None:
    view = _carved_stack().view()
    here = view.world_to_index(CENTRE[None])[0]
    assert view.traversable[tuple(here)]
    assert np.count_nonzero(view.free) > 1000
    assert np.count_nonzero(view.occupied) == 0
    assert len(view.frontier_clusters(1)) >= 1


@pytest.mark.parametrize("planner_id", planner_ids())
def test_plan_on_a_handmade_map(planner_id: str) -> None:
    stack = _carved_stack()
    view = stack.view()
    planner = make(planner_id)
    planner.reset(_context())
    obs = Observation(
        time=0.0,
        pose=Pose(CENTRE.copy(), 0.0),
        velocity=np.zeros(3),
        map=view,
        last_outcome=PlanOutcome.NONE,
    )
    plan = planner.plan(obs)
    assert isinstance(plan, Plan)
    for key, value in plan.info.items():
        assert isinstance(key, str)
        assert isinstance(value, (int, float, str)), (key, value)
    if plan.done:
        return
    wps = np.asarray(plan.waypoints, dtype=np.float64)
    assert wps.ndim == 2
    assert wps.shape[1] == 4
    assert len(wps) >= 1
    assert np.all(np.isfinite(wps))
    assert np.all(wps[:, :3] >= BOUNDS_MIN)
    assert np.all(wps[:, :3] <= BOUNDS_MAX)
    idx = view.world_to_index(wps[:, :3])
    assert np.all(view.in_bounds(idx))
    assert np.all(view.traversable[idx[:, 0], idx[:, 1], idx[:, 2]])
    assert plan.horizon_s is None or (math.isfinite(plan.horizon_s) and plan.horizon_s >= 0.0)


@pytest.mark.parametrize("planner_id", planner_ids())
def test_plan_on_a_handmade_map_is_repeatable(planner_id: str) -> None:
    """Same map, same seed: the same plan (a planner's only randomness is `ctx.rng`)."""
    plans = []
    for _ in range(2):
        planner = make(planner_id)
        planner.reset(_context(seed=7))
        obs = Observation(0.0, Pose(CENTRE.copy(), 0.0), np.zeros(3), _carved_stack().view(),
                          PlanOutcome.NONE)
        plans.append(planner.plan(obs))
    assert plans[0].done == plans[1].done
    np.testing.assert_array_equal(plans[0].waypoints, plans[1].waypoints)


def test_classic_flies_toward_the_carved_frontier() -> None:
    """The ball's surface is one big frontier: Classic must not give up on it."""
    view = _carved_stack().view()
    planner = make("classic")
    planner.reset(_context())
    plan = planner.plan(
        Observation(0.0, Pose(CENTRE.copy(), 0.0), np.zeros(3), view, PlanOutcome.NONE)
    )
    assert not plan.done, plan.info
    assert plan.waypoints.shape[0] >= 1
    assert plan.horizon_s == 0.0
    assert plan.info["clusters"] >= 1
    assert 0.0 < plan.info["path_m"] < BALL_RADIUS


def test_versions_of_a_planner_do_not_inherit_each_other() -> None:
    """An id keeps the code its results were made with: a newer version never subclasses an
    older one (it would change with it), nor an older one a newer; versions share a base
    class and differ in their configuration."""
    by_name: dict[str, list[PlannerSpec]] = {}
    for s in specs():
        by_name.setdefault(s.name, []).append(s)
    for versions in by_name.values():
        for a, b in itertools.permutations(versions, 2):
            assert a.cls is b.cls or not issubclass(a.cls, b.cls), (
                f"{a.id} ({a.cls.__qualname__}) subclasses {b.id} ({b.cls.__qualname__})")


def test_every_id_is_a_distinct_planner() -> None:
    """No two ids run the same class with the same default configuration."""
    seen: dict[tuple[type, str], str] = {}
    for s in specs():
        key = (s.cls, s.config_model().model_dump_json())
        assert key not in seen, f"{s.id} is {seen[key]} again"
        seen[key] = s.id


def test_aep_v1_and_v2_differ_in_their_fallback_only() -> None:
    v1, v2 = spec("aep-v1"), spec("aep-v2")
    assert v1.cls is not v2.cls
    assert not issubclass(v1.cls, v2.cls) and not issubclass(v2.cls, v1.cls)
    first, second = v1.config_model().model_dump(), v2.config_model().model_dump()
    assert first["fallback"] is None and second["fallback"] is not None
    assert {k: v for k, v in first.items() if k != "fallback"} == {
        k: v for k, v in second.items() if k != "fallback"}


def test_aep_v4_differs_from_v1_in_its_global_step_only() -> None:
    v1, v4 = spec("aep-v1").config_model().model_dump(), spec("aep-v4").config_model().model_dump()
    step = {"goal_gain_m3", "hover_when_no_goal"}
    assert {k for k in v1 if v1[k] != v4[k]} == step
