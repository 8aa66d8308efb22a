"""End-to-end episodes: Classic on MAZE for a short time, and scripted flights."""

from __future__ import annotations

import itertools

import numpy as np
import numpy.typing as npt
import pytest

from areas import load_area, load_ground_truth
from planners.registry import make
from sim.config import preset
from sim.episode import run_episode
from sim.interface import Observation, Plan, PlannerContext, PlanOutcome
from sim.occupancy import OccupancyMap
from sim.recording import Recording
from sim.result import EpisodeResult, RunStatus
from sim.search_checks import plan_is_clear


def _run(seed: int, preset_name: str, seconds: float, *, charge_planning_time: bool = True,
         **kwargs: object) -> EpisodeResult:
    area = load_area("maze")
    config = preset(preset_name)
    if not charge_planning_time:
        config = config.model_copy(update={"planning_time_charge": "none"})
    return run_episode(area, load_ground_truth(area), make("classic"), config, seed,
                       planner_name="classic-v1", preset_name=preset_name, seconds=seconds,
                       **kwargs)  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def short_run() -> EpisodeResult:
    # Sensor and odometry noise on, but the planner's wall time is not charged to the clock:
    # the flight is then the same on every machine, so the thresholds below hold everywhere.
    return _run(0, "default", 60.0, charge_planning_time=False)


def test_explored_volume_grows_without_collision(short_run: EpisodeResult) -> None:
    assert short_run.status is RunStatus.SUCCEEDED
    assert short_run.collisions == 0
    volume = short_run.volume_m3
    assert len(volume) == 61  # one sample per simulated second, t = 0 .. 60
    assert np.all(np.diff(volume) >= 0)  # known voxels never become unknown again
    assert volume[-1] > 1.5 * volume[0] > 0
    assert short_run.path_length_m > 5.0
    assert short_run.iterations >= 3
    assert 0 < short_run.coverage < 1


def test_surface_metrics_are_sane(short_run: EpisodeResult) -> None:
    surface = short_run.surface
    # What is reconstructed lies on the truth. After one noisy minute, seeds 0-3 give precision
    # 0.69-0.94 and RMSE 0.025-0.047 m; a wrong camera frame or pose would give far less.
    assert surface.precision > 0.7
    assert 0 < surface.recall < 0.5  # a minute covers a small part of the maze
    assert surface.rmse_m < 0.06
    assert len(short_run.recall) == 3  # snapshots at 20, 40, 60 s
    assert np.all(np.diff(short_run.recall) >= -0.01)


def test_same_seed_without_time_charge_is_repeatable(tmp_path: object) -> None:
    first = _run(3, "exact", 30.0)
    second = _run(3, "exact", 30.0)
    np.testing.assert_array_equal(first.volume_m3, second.volume_m3)
    assert first.path_length_m == second.path_length_m
    assert first.iterations == second.iterations
    assert first.surface == second.surface


def test_recording_holds_the_flight(tmp_path: object) -> None:
    from pathlib import Path

    path = Path(str(tmp_path)) / "recording.npz"
    result = _run(1, "exact", 25.0, recording_path=path)
    rec = Recording(path)
    assert rec.header["area"] == "maze"
    assert rec.header["grid_shape"] == [200, 200, 25]
    assert len(rec.poses) >= 25 * 10  # 10 Hz
    final = rec.map_state_at(25.0)
    assert np.count_nonzero(final) * 0.1**3 == pytest.approx(result.explored_volume_m3, rel=0.05)
    assert len(rec.plan_at(25.0)) >= 1


def test_planner_exception_fails_the_run() -> None:
    class Broken:
        def reset(self, ctx: object) -> None:
            pass

        def plan(self, obs: object) -> object:
            raise RuntimeError("boom")

    area = load_area("maze")
    result = run_episode(area, load_ground_truth(area), Broken(), preset("exact"), 0,
                         seconds=20.0)  # type: ignore[arg-type]
    assert result.status is RunStatus.FAILED
    assert "boom" in result.reason


class _Shuttle:
    """Flies between two points near the start, asking to be asked again mid-flight; every
    other mid-flight call keeps the current trajectory."""

    def __init__(self, replan_s: float, finish_after_calls: int = 10**9) -> None:
        self.replan_s = replan_s
        self.finish_after_calls = finish_after_calls
        self.calls: list[tuple[float, str, float]] = []

    def reset(self, ctx: PlannerContext) -> None:
        self.start = ctx.start.position.copy()

    def plan(self, obs: Observation) -> Plan:
        speed = float(np.linalg.norm(obs.velocity))
        self.calls.append((obs.time, obs.last_outcome.value, speed))
        if len(self.calls) > self.finish_after_calls:
            return Plan.finished("enough")
        if obs.last_outcome is PlanOutcome.FLYING and len(self.calls) % 2 == 0:
            return Plan.keep_flying(self.replan_s)
        side = 1.0 if len(self.calls) % 12 < 6 else -1.0
        goal = self.start + np.array([0.3 * side, 0.2 * side, 0.0])
        return Plan(np.array([[*goal, 0.5 * side]]), replan_s=self.replan_s)


def _shuttle_run(planner: _Shuttle, seconds: float) -> EpisodeResult:
    area = load_area("maze")
    return run_episode(area, load_ground_truth(area), planner, preset("exact"), 0,  # type: ignore[arg-type]
                       seconds=seconds)


def test_replanning_in_flight_starts_from_the_moving_state() -> None:
    planner = _Shuttle(replan_s=0.25)
    result = _shuttle_run(planner, 16.0)
    assert result.status is RunStatus.SUCCEEDED, result.reason
    assert result.collisions == 0
    flying = [c for c in planner.calls if c[1] == "flying"]
    assert len(flying) > 10
    # Asked while moving, at the requested period of flight.
    assert max(c[2] for c in flying) > 0.1
    times = np.array([c[0] for c in planner.calls])
    assert np.median(np.diff(times)) == pytest.approx(0.25, abs=0.02)
    # The vehicle shuttled: it flew much more than one 0.72 m leg.
    assert result.path_length_m > 2.0


def test_finishing_in_flight_ends_the_run() -> None:
    planner = _Shuttle(replan_s=0.25, finish_after_calls=5)
    result = _shuttle_run(planner, 14.0)
    assert result.status is RunStatus.SUCCEEDED
    assert "enough" in result.reason
    assert planner.calls[-1][1] == "flying"
    assert result.simulated_until == pytest.approx(planner.calls[-1][0], abs=0.02)
    assert len(result.volume_m3) == 15  # the curve is still filled to the end


def test_keeping_with_a_zero_period_does_not_stall_the_clock() -> None:
    class ZeroKeep(_Shuttle):
        def plan(self, obs: Observation) -> Plan:
            if obs.last_outcome in (PlanOutcome.FLYING, PlanOutcome.INVALID):
                self.calls.append((obs.time, obs.last_outcome.value, 0.0))
                return Plan.keep_flying(0.0)
            return super().plan(obs)

    planner = ZeroKeep(replan_s=0.25)
    result = _shuttle_run(planner, 10.0)
    assert result.status is RunStatus.SUCCEEDED, result.reason
    times = np.array([c[0] for c in planner.calls])
    assert np.all(np.diff(times) > 0.1)  # asked again only after the flight's own period


def test_keeping_without_a_period_is_not_asked_again_that_flight() -> None:
    """`Plan(keep=True)` with no `replan_s`: the flight goes on to its end unasked."""

    class KeepOnce(_Shuttle):
        def plan(self, obs: Observation) -> Plan:
            if obs.last_outcome is PlanOutcome.FLYING:
                self.calls.append((obs.time, obs.last_outcome.value, 0.0))
                return Plan(keep=True)
            return super().plan(obs)

    planner = KeepOnce(replan_s=0.25)
    result = _shuttle_run(planner, 16.0)
    assert result.status is RunStatus.SUCCEEDED, result.reason
    outcomes = [c[1] for c in planner.calls]
    assert outcomes.count("flying") >= 2
    # Each flight is asked once in flight, then the next call is at its end.
    assert all(a != "flying" or b != "flying" for a, b in itertools.pairwise(outcomes))


class _Dash:
    """One straight flight of 3-4 m from the start, yawed along it; then finishes. Records the
    calls as (time, last outcome, position, speed)."""

    def __init__(self) -> None:
        self.goal: np.ndarray | None = None
        self.calls: list[tuple[float, str, np.ndarray, float]] = []

    def reset(self, ctx: PlannerContext) -> None:
        self.start = ctx.start.position.copy()

    def plan(self, obs: Observation) -> Plan:
        self.calls.append((obs.time, obs.last_outcome.value, obs.pose.position.copy(),
                           float(np.linalg.norm(obs.velocity))))
        if self.goal is not None:
            return Plan.finished("dashed")
        view = obs.map
        here = obs.pose.position
        centres = view.index_to_world(np.argwhere(view.traversable))
        offsets = centres - here
        distance = np.linalg.norm(offsets, axis=1)
        level = np.abs(offsets[:, 2]) < 0.05
        for i in np.flatnonzero(level & (distance > 3.0) & (distance < 4.0)):
            if plan_is_clear(view.traversable, view.free, view.origin, view.voxel_size, here,
                             centres[i][None]) == 1:
                self.goal = centres[i]
                break
        assert self.goal is not None, "no straight 3-4 m flight from the start"
        yaw = float(np.arctan2(*(self.goal - here)[1::-1]))
        return Plan(np.array([[*self.goal, yaw]]))


def _dash_run(monkeypatch: pytest.MonkeyPatch, obstacle_at: float | None) -> tuple[
    _Dash, EpisodeResult, np.ndarray | None
]:
    """A dash in MAZE; with `obstacle_at`, the map is told of an obstacle at that fraction of
    the way, from the third occupancy update after the plan on (as a thin surface the map had
    cleared from afar and finds again)."""
    planner = _Dash()
    obstacle: list[np.ndarray] = []
    updates = [0]
    original = OccupancyMap.integrate

    def integrate(self: OccupancyMap, origin: npt.ArrayLike, endpoints: npt.ArrayLike,
                  hit: npt.ArrayLike) -> int:
        if planner.goal is not None and obstacle_at is not None:
            if not obstacle:
                obstacle.append(planner.start + obstacle_at * (planner.goal - planner.start))
            updates[0] += 1
            if updates[0] > 2:
                endpoints = np.vstack([np.asarray(endpoints), obstacle[0][None]])
                hit = np.append(np.asarray(hit), True)
        return original(self, origin, endpoints, hit)

    monkeypatch.setattr(OccupancyMap, "integrate", integrate)
    area = load_area("maze")
    result = run_episode(area, load_ground_truth(area), planner, preset("exact"), 0,  # type: ignore[arg-type]
                         seconds=15.0)
    return planner, result, obstacle[0] if obstacle else None


def test_an_obstacle_found_on_the_path_in_flight_stops_the_vehicle_before_it(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    planner, result, obstacle = _dash_run(monkeypatch, obstacle_at=0.85)
    assert obstacle is not None
    assert result.safety_stops == 1
    assert result.collisions == 0
    _, outcome, stopped_at, speed = planner.calls[-1]
    assert outcome == "blocked"
    assert speed < 0.1  # asked again at rest
    assert planner.goal is not None
    flown = np.linalg.norm(stopped_at - planner.start)
    # It was under way when the obstacle appeared: found at the third update (0.6 s after the
    # plan), when one return is enough to make its voxel occupied, it flew on while braking.
    assert flown > 0.5
    # Stopped short of the obstacle by more than the vehicle's radius.
    assert np.linalg.norm(obstacle - stopped_at) > 0.35
    assert flown < np.linalg.norm(obstacle - planner.start)


def test_without_a_new_obstacle_the_flight_is_not_stopped(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    planner, result, _ = _dash_run(monkeypatch, obstacle_at=None)
    assert result.safety_stops == 0
    _, outcome, reached, _ = planner.calls[-1]
    assert outcome == "reached"
    assert planner.goal is not None
    assert np.linalg.norm(reached - planner.goal) < 0.1


def test_result_reports_every_registered_metric(short_run: EpisodeResult) -> None:
    from sim.measures import metric_infos

    keys = [m.key for m in metric_infos()]
    assert list(short_run.metrics) == keys
    payload = short_run.to_json()
    assert payload["metrics"]["coverage"] == short_run.coverage
    assert payload["metrics"]["fscore"] == short_run.surface.fscore
    assert payload["metrics"]["iterations"] == short_run.iterations
