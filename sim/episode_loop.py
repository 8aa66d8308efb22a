"""The episode's loop: simulated time, physics, when to ask the planner and what its thinking
costs (see `sim.episode` for the parts it drives).

The loop is a generator (`EpisodeLoop.steps`) that yields a `PlanRequest` whenever it needs a
plan and is sent a `PlanReply`: `run_with` drives it with a planner object, an environment
(`flybo.envs`) drives it with an agent's actions; both fly the same loop.
"""

from __future__ import annotations

import math
import time
from collections.abc import Generator
from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np
import numpy.typing as npt

from areas.area import Area, GroundTruth
from sim.config import EpisodeConfig
from sim.episode_recorder import EpisodeRecorder
from sim.flight import Flight, hold_at, startup_spin
from sim.geometry import Pose
from sim.heap import release_free_heap
from sim.interface import Observation, Plan, PlannerContext, PlannerLike, PlanOutcome
from sim.measures import EpisodeCounters, EpisodeEnd, EpisodeView, Measure, make_measures
from sim.measures.base import ProgressCallback
from sim.mesh_distance import distance_to_mesh
from sim.plan_check import PlanChecker, Start
from sim.planning_charge import PlanningCharge
from sim.result import EpisodeResult, RunStatus
from sim.safety_monitor import SafetyMonitor
from sim.sensing import RandomStreams, Sensing
from sim.stage_costs import StageCosts
from sim.trajectory import TrajectorySample
from sim.tsdf import surface_block_count
from sim.world import World

__all__ = ["EpisodeLoop", "PlanReply", "PlanRequest", "call_planner"]

# Surface samples of the ground truth that size the TSDF's block table.
TSDF_ESTIMATE_POINTS = 200_000


@dataclass(frozen=True)
class PlanRequest:
    """The loop waits for a plan: `observation` is what the planner sees, `in_flight` whether
    it is asked mid-flight (the flight goes on while it thinks)."""

    observation: Observation
    in_flight: bool


@dataclass(frozen=True)
class PlanReply:
    """What came back: `plan` (anything; the loop checks it is a `Plan`), the call's wall time
    (less numba's compiler for a planner in this process, `PlanningCharge.settle`),
    the simulated seconds to charge for it, or the failure that ended the planner's run."""

    plan: object = None
    wall_s: float = 0.0
    charge_s: float = 0.0
    failure: str | None = None


def call_planner(planner: PlannerLike, request: PlanRequest, charge: PlanningCharge,
                 platform_errors: tuple[type[BaseException], ...]) -> PlanReply:
    """Ask `planner`, timing the call and charging it as `charge` says. A planner's exception
    becomes a failure; `platform_errors` (a worker's time limit) propagate."""
    t0, clocks = time.perf_counter(), charge.read()
    try:
        plan = planner.plan(request.observation)
    except platform_errors:
        raise
    except Exception as exc:  # a planner bug ends its run, not the process
        return PlanReply(failure=f"planner raised {type(exc).__name__}: {exc}")
    wall, charged = charge.settle(time.perf_counter() - t0, clocks)
    return PlanReply(plan, wall, charged)


@dataclass(frozen=True)
class Ending:
    status: RunStatus
    reason: str


class _PlannerFailedError(Exception):
    """The planner raised, returned something else than a Plan, or the vehicle crashed while
    it thought; the message is the run's reason."""


class EpisodeLoop:
    """One run's parts and its loop (see the module docstring)."""

    def __init__(self, area: Area, ground_truth: GroundTruth, config: EpisodeConfig, seed: int,
                 planner_name: str, preset_name: str, seconds: float,
                 progress: ProgressCallback | None) -> None:
        if not (seconds > 0 and math.isfinite(seconds)):
            raise ValueError(f"seconds must be a positive number, got {seconds}")
        self.area, self.cfg = area, config
        self.seed, self.planner_name, self.preset_name = seed, planner_name, preset_name
        self.t_end = float(seconds)
        self.wall0 = time.perf_counter()
        self.streams = RandomStreams.from_seed(seed)
        self.costs = StageCosts()
        # The TSDF's block table is sized for the area's surface at the start (see
        # `sim.tsdf.EXPECTED_BLOCK_MARGIN`); 200,000 samples count its blocks to within 2 %.
        expected_blocks = surface_block_count(
            ground_truth.surface.sample(TSDF_ESTIMATE_POINTS), config.tsdf)
        self.sensing = Sensing(area, config, self.streams, self.costs, expected_blocks)
        self.checker = PlanChecker(area, config, self.sensing.mapping)
        self.monitor = SafetyMonitor(config, self.sensing.mapping, self.costs)
        self.world = World(area.vertices, area.triangles, area.start.position, config.limits,
                           config.physics)
        self.yaw = area.start.yaw
        self.recorder = EpisodeRecorder(area, config, planner_name, seed, preset_name)
        self.counters = EpisodeCounters()
        self.view = EpisodeView(area, ground_truth, config, seed, self.sensing.mapping,
                                self.sensing.tsdf, self.counters,
                                partial(distance_to_mesh, area.vertices, area.triangles),
                                progress)
        self.measures: list[Measure] = make_measures()
        self.planned_from = area.start.position.copy()
        self.frame_period = 1.0 / config.camera.rate_hz
        self.next_frame = 0.0
        self.charge_record: dict[str, Any] = {"mode": "none"}

    def close(self) -> None:
        self.world.close()

    # -- the loop ---------------------------------------------------------------------------

    def begin(self) -> PlannerContext:
        """Prepare the run; the context is what the planner is reset with."""
        self.wall0 = time.perf_counter()
        self.sensing.clear_start_sphere(self.area.start.position, self.area.voxel_size)
        for measure in self.measures:
            measure.reset(self.view)
        return self._context()

    def steps(self) -> Generator[PlanRequest, PlanReply, Ending]:
        """The run as a generator: it yields whenever it needs a plan and is sent the reply;
        it returns how the run ended. Whoever drives it is the planner (`run_with`, or an
        environment's `step`)."""
        # Reference state at rest, in the map frame: where the next trajectory starts.
        rest = np.array([*self.area.start.position, self.area.start.yaw])
        self._on_frame_boundaries()  # the first frame, at t = 0
        return (yield from self._fly(rest))

    def run_with(self, planner: PlannerLike, charge: PlanningCharge,
                 platform_errors: tuple[type[BaseException], ...]) -> EpisodeResult:
        planner.reset(self.begin())
        steps = self.steps()
        try:
            request = next(steps)
            while True:
                request = steps.send(call_planner(planner, request, charge, platform_errors))
        except StopIteration as stop:
            ending: Ending = stop.value
        self.charge_record = charge.describe()
        return self.finish(ending)

    def _context(self) -> PlannerContext:
        a = self.area
        return PlannerContext(
            area=a.name, bounds_min=a.bounds_min.copy(), bounds_max=a.bounds_max.copy(),
            start=Pose(a.start.position.copy(), a.start.yaw), limits=self.cfg.limits,
            safety_radius_m=self.cfg.safety_radius_m, camera=self.cfg.camera,
            rng=self.streams.planner, indoor=a.info.indoor,
        )

    def _fly(self, rest: npt.NDArray[np.float64]) -> Generator[PlanRequest, PlanReply, Ending]:
        """Fly until the time limit or an earlier end; `rest` is (4,) x, y, z, yaw."""
        cfg = self.cfg
        hold = hold_at(rest)
        flight = startup_spin(rest, self.world.time, cfg.limits) if cfg.startup_spin else None
        outcome = PlanOutcome.NONE
        failures = 0
        while self.world.time < self.t_end - 1e-9:
            if flight is None:
                try:
                    plan = yield from self._ask(outcome)
                except _PlannerFailedError as exc:
                    return self._failed(str(exc))
                if plan.done:
                    return Ending(RunStatus.SUCCEEDED, _finished(plan))
                # Fly from where odometry says the vehicle is, as the planner saw it: the
                # reference it last held differs by the tracking error and the drift since.
                flight, outcome = self._accept(plan, np.array([*self.planned_from, rest[3]]))
                if flight is None:
                    failures += 1
                    if failures >= cfg.max_failed_plans:
                        return Ending(RunStatus.FAILED,
                                       f"{failures} consecutive plans were {outcome.value}")
                    if not self._hold(hold, cfg.failed_plan_hover_s):
                        return Ending(RunStatus.CRASHED, "collision while hovering")
                    continue
                failures = 0
            elif flight.replan_due(self.world.time):
                # A rejected mid-flight plan costs nothing but the call: the checked flight
                # goes on, so it does not count toward `max_failed_plans`.
                try:
                    flight, outcome, ending = yield from self._replan_in_flight(flight, outcome)
                except _PlannerFailedError as exc:
                    return self._failed(str(exc))
                if ending is not None:
                    return ending
            if not self._physics_step(flight.reference(self.world.time)):
                return Ending(RunStatus.CRASHED, "collision with the scene")
            if flight.finished(self.world.time):
                hold = flight.end_state()
                rest = np.array([*hold.position, hold.yaw])
                outcome = PlanOutcome.BLOCKED if flight.braking else PlanOutcome.REACHED
                flight = None
            elif self.monitor.newly_blocked(flight, self.world.time,
                                            self.sensing.occupancy_updates):
                flight = self._safety_stop(flight)
        return Ending(RunStatus.SUCCEEDED, "time limit reached")

    def _failed(self, reason: str) -> Ending:
        crashed = self.counters.collisions > 0  # while hovering or flying as it thought
        return Ending(RunStatus.CRASHED if crashed else RunStatus.FAILED, reason)

    def _replan_in_flight(self, flight: Flight, outcome: PlanOutcome) -> Generator[
        PlanRequest, PlanReply, tuple[Flight, PlanOutcome, Ending | None]
    ]:
        """Ask the planner mid-flight; the new plan replaces the rest of `flight` only if it
        passes the checks, else `flight` is flown on. Returns the flight to follow, the outcome
        the planner sees next, and the ending if the run ends here."""
        plan = yield from self._ask(PlanOutcome.FLYING, flight)
        if plan.done:
            return flight, outcome, Ending(RunStatus.SUCCEEDED, _finished(plan))
        now = self.world.time
        if plan.keep:
            period = plan.replan_s
            if period is not None and not (math.isfinite(period) and period > 0):
                # A zero period would ask again without the clock moving.
                flight.schedule_replan(now, flight.replan_s)
                return flight, PlanOutcome.INVALID, None
            flight.schedule_replan(now, period)
            return flight, PlanOutcome.FLYING, None
        new, result = self._accept(plan, flight.reference(now))
        if new is None:
            flight.schedule_replan(now, flight.replan_s)
            return flight, result, None
        return new, result, None

    def _accept(self, plan: Plan, start: Start) -> tuple[Flight | None, PlanOutcome]:
        """The plan checked and, if it can be flown, recorded and guarded."""
        flight, outcome, waypoints = self.checker.check(plan, start, self.world.time)
        if flight is not None:
            self.recorder.plan(self.world.time, waypoints)
            self.monitor.guard(flight, self.sensing.occupancy_updates)
        return flight, outcome

    def _safety_stop(self, flight: Flight) -> Flight:
        """Brake from the current reference state; fly on as planned if no stop is possible."""
        stop = self.monitor.stop(flight, self.world.time)
        if stop is None:
            return flight
        self.counters.safety_stops += 1
        self.recorder.plan(self.world.time, stop.trajectory.waypoints)
        return stop

    # -- the planner ------------------------------------------------------------------------

    def _ask(self, outcome: PlanOutcome, flight: Flight | None = None) -> Generator[
        PlanRequest, PlanReply, Plan
    ]:
        """The planner's next plan; its thinking time is charged as the reply says."""
        obs = self.observation(outcome)
        self.planned_from = obs.pose.position
        reply = yield PlanRequest(obs, in_flight=flight is not None)
        if reply.failure is not None:
            raise _PlannerFailedError(reply.failure)
        self.costs.planner += reply.wall_s
        self.counters.planning_ms.append(1000.0 * reply.wall_s)
        self.counters.charged_s.append(reply.charge_s)
        plan = reply.plan
        if not isinstance(plan, Plan):
            raise _PlannerFailedError(f"planner returned {type(plan).__name__}, not a Plan")
        if reply.charge_s > 0:
            self._think(reply.charge_s, flight)
        return plan

    def _think(self, seconds: float, flight: Flight | None) -> None:
        """The simulated clock runs on while the planner thinks: the vehicle hovers, as in a
        real-time system, or, asked mid-flight, flies on along the current trajectory."""
        if flight is not None:
            if not self._follow(flight, seconds):
                raise _PlannerFailedError("collision while flying")
            return
        here = self._estimated_pose()
        hold = TrajectorySample(here.position, np.zeros(3), np.zeros(3), here.yaw, 0.0)
        if not self._hold(hold, seconds):
            raise _PlannerFailedError("collision while hovering")

    # -- physics and frames -----------------------------------------------------------------

    def _follow(self, flight: Flight, seconds: float) -> bool:
        """Fly on along `flight` for `seconds` (holding its end if it ends first)."""
        end = self.world.time + seconds
        while self.world.time < min(end, self.t_end) - 1e-9:
            if not self._physics_step(flight.reference(self.world.time)):
                return False
        return True

    def _hold(self, hold: TrajectorySample, seconds: float) -> bool:
        end = self.world.time + seconds
        while self.world.time < min(end, self.t_end) - 1e-9:
            if not self._physics_step(hold):
                return False
        return True

    def _physics_step(self, ref: TrajectorySample) -> bool:
        """One physics step toward `ref` (map frame); False on a collision."""
        t0 = time.perf_counter()
        before = self.world.position
        # The controller sees the estimated position, so it flies the map-frame reference
        # shifted by the odometry drift in the true world.
        drift = self.sensing.drift.offset
        shifted = TrajectorySample(ref.position - drift, ref.velocity, ref.acceleration,
                                   ref.yaw, ref.yaw_rate)
        contact = self.world.step(shifted)
        self.yaw = ref.yaw
        self.counters.path_length_m += float(np.linalg.norm(self.world.position - before))
        self.costs.physics += time.perf_counter() - t0
        if contact is not None:
            self.counters.collisions += 1
            return False
        self._on_frame_boundaries()
        return True

    def _on_frame_boundaries(self) -> None:
        now = self.world.time
        while self.next_frame <= now + 1e-9:
            self._camera_frame(self.next_frame)
            self.next_frame += self.frame_period
        self.recorder.pose(now, self.world.position, self.yaw)

    def _camera_frame(self, stamp: float) -> None:
        self.sensing.frame(stamp, Pose(self.world.position.copy(), self.yaw))
        t0 = time.perf_counter()
        for measure in self.measures:
            measure.update(self.view, stamp)
        t1 = time.perf_counter()
        self.recorder.frame(stamp, self.sensing)
        self.costs.metrics += t1 - t0
        self.costs.recording += time.perf_counter() - t1

    def observation(self, outcome: PlanOutcome) -> Observation:
        """What a planner asked now would see."""
        return Observation(
            time=self.world.time, pose=self._estimated_pose(),
            velocity=self.world.velocity.copy(), map=self.sensing.mapping.view(),
            last_outcome=outcome,
        )

    def _estimated_pose(self) -> Pose:
        return self.sensing.estimate(Pose(self.world.position.copy(), self.yaw))

    # -- the end ----------------------------------------------------------------------------

    def finish(self, ending: Ending) -> EpisodeResult:
        """Score the run (once it has ended)."""
        simulated_until = self.world.time
        # Scoring needs no physics and no camera; the world's collision meshes and the camera's
        # scene go before the final mesh is made.
        self.world.close()
        self.sensing.camera.close()
        t0 = time.perf_counter()
        self.recorder.finish(simulated_until, self.sensing)
        self.costs.recording += time.perf_counter() - t0
        t0 = time.perf_counter()
        end = EpisodeEnd(ending.status, self.t_end, simulated_until)
        done: dict[str, Any] = {}
        for measure in self.measures:
            # The final measures (the mesh, its scoring) each take hundreds of MiB for a
            # moment: what the flight and the previous measure freed goes back first.
            release_free_heap()
            done[measure.name] = measure.result(self.view, end, {
                name: done[name] for name in measure.requires})
        metrics: dict[str, float | None] = {}
        for measure in self.measures:
            metrics.update(measure.scalars(done[measure.name]))
        self.costs.metrics += time.perf_counter() - t0
        succeeded = ending.status is RunStatus.SUCCEEDED
        volume, recall = done["explored_volume"], done["recall_series"]
        mesh = done["reconstruction"]
        return EpisodeResult(
            area=self.area.name, planner=self.planner_name, seed=self.seed,
            preset=self.preset_name, status=ending.status, reason=ending.reason,
            sim_seconds=self.t_end if succeeded else simulated_until,
            simulated_until=simulated_until, wall_seconds=time.perf_counter() - self.wall0,
            explored_volume_m3=self.sensing.mapping.occupancy.explored_volume_m3,
            observable_volume_m3=self.view.truth.observable_volume_m3,
            coverage=done["coverage"].coverage, collisions=done["collisions"],
            path_length_m=done["path_length"], iterations=done["planning"].iterations,
            planning_times_ms=done["planning"].wall_ms, surface=done["surface"],
            volume_times=volume.times, volume_m3=volume.values,
            recall_times=recall.times, recall=recall.values,
            frame_costs_ms=self.costs.per_frame_ms(),
            mesh_vertices=mesh.vertices, mesh_triangles=mesh.triangles,
            safety_stops=done["safety_stops"], metrics=metrics,
            charged_s=done["planning"].charged_s, charge=dict(self.charge_record),
        )


def _finished(plan: Plan) -> str:
    return f"planner finished: {plan.info.get('reason', 'done')}"
