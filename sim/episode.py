"""The episode runner: one planner exploring one area, from start to plateau.

`run_episode` is the single entry point used by the CLI and the workers. Per physics step the
vehicle tracks the reference; at each camera frame the simulator renders depth where a map needs
it, adds noise, fuses the frame, and samples the metrics; whenever the planner's horizon runs out
it is asked again (at rest, or mid-flight when the plan asked for it with `Plan.replan_s`).
While a plan is flown, every occupancy update is checked against the rest of its path: an obstacle
found since the plan was accepted, close enough to that path for the vehicle to touch it, makes
the vehicle brake to a stop (a safety stop) and the planner is asked again with the outcome
BLOCKED.
The run ends at the time limit, when the planner says done (the rest of the curve is then flat
and not simulated), on a collision (`crashed`) or on a planner failure.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt

from areas.area import Area, GroundTruth
from sim.camera import DepthCamera
from sim.config import EpisodeConfig
from sim.geometry import Pose
from sim.interface import Observation, Plan, PlannerContext, PlannerLike, PlanOutcome
from sim.map_view import MappingStack
from sim.metrics import coverage, sdf_surface_recall, surface_scores
from sim.noise import OdometryDrift, add_depth_noise
from sim.occupancy import StateGrid
from sim.recording import RecordingWriter
from sim.result import EpisodeResult, RunStatus
from sim.search_checks import path_meets_new_obstacle, plan_is_clear
from sim.trajectory import (
    Trajectory,
    TrajectoryError,
    TrajectorySample,
    plan_trajectory,
    plan_trajectory_from,
    stop_trajectory,
)
from sim.tsdf import TsdfVolume
from sim.world import World

ProgressCallback = Callable[[float, float], None]


@dataclass
class _Streams:
    """Independent random streams, so that switching one noise off leaves the others alone."""

    depth: np.random.Generator
    odometry: np.random.Generator
    planner: np.random.Generator

    @classmethod
    def from_seed(cls, seed: int) -> _Streams:
        depth, odometry, planner = (np.random.default_rng(s) for s in
                                    np.random.SeedSequence(seed).spawn(3))
        return cls(depth, odometry, planner)


@dataclass
class _Costs:
    """Accumulated wall time per stage, seconds."""

    render: float = 0.0
    occupancy: float = 0.0
    tsdf: float = 0.0
    physics: float = 0.0
    planner: float = 0.0
    metrics: float = 0.0
    checks: float = 0.0  # the in-flight check of the rest of the path (safety stops)
    frames: int = 0

    def per_frame_ms(self) -> dict[str, float]:
        n = max(self.frames, 1)
        return {k: 1000.0 * getattr(self, k) / n for k in
                ("render", "occupancy", "tsdf", "physics", "planner", "metrics", "checks")}


@dataclass
class _Flight:
    """The trajectory being flown and when to ask the planner again."""

    trajectory: Trajectory
    start_time: float
    stop_after: float  # seconds into the trajectory
    stop_leg: int
    replan_s: float | None = None  # ask again this often in flight (None: only at the end)
    next_replan: float = math.inf  # simulated time of the next mid-flight question
    # The map the path was checked against; None for flights the map does not guard (the
    # start-up turn in place, a safety stop).
    checked_on: StateGrid | None = None
    checked_at_update: int = 0  # occupancy updates counted when the path was last checked
    braking: bool = False  # a safety stop

    def reference(self, now: float) -> TrajectorySample:
        return self.trajectory.sample(min(now - self.start_time, self.stop_after))

    def finished(self, now: float) -> bool:
        return now - self.start_time >= self.stop_after - 1e-9

    def replan_due(self, now: float) -> bool:
        return now >= self.next_replan - 1e-9 and not self.finished(now)

    def schedule_replan(self, now: float, replan_s: float | None) -> None:
        self.replan_s = replan_s
        self.next_replan = now + replan_s if replan_s is not None else math.inf


@dataclass
class _Series:
    volume_times: list[float] = field(default_factory=list)
    volume: list[float] = field(default_factory=list)
    recall_times: list[float] = field(default_factory=list)
    recall: list[float] = field(default_factory=list)


def _subsample(points: npt.NDArray[np.float32], count: int, seed: int) -> npt.NDArray[np.float32]:
    """At most `count` of `points`, drawn without replacement, in their original order."""
    if len(points) <= count:
        return points
    rng = np.random.default_rng(seed)
    return points[np.sort(rng.choice(len(points), size=count, replace=False))]


def run_episode(
    area: Area,
    ground_truth: GroundTruth,
    planner: PlannerLike,
    config: EpisodeConfig,
    seed: int,
    *,
    planner_name: str = "planner",
    preset_name: str = "custom",
    seconds: float | None = None,
    recording_path: Path | None = None,
    progress: ProgressCallback | None = None,
) -> EpisodeResult:
    """Run one exploration episode and measure it.

    Args:
        seconds: simulated time limit; the area's plateau time when None.
        recording_path: where to write the run recording (`.npz`), if anywhere.
        progress: called about once per simulated second with (time, explored volume m³).
    """
    runner = _EpisodeRunner(area, ground_truth, planner, config, seed, planner_name, preset_name,
                            seconds if seconds is not None else area.plateau_s, progress)
    try:
        result = runner.run()
    finally:
        runner.close()
    if recording_path is not None:
        runner.recording.save(recording_path)
    return result


class _EpisodeRunner:
    def __init__(
        self,
        area: Area,
        ground_truth: GroundTruth,
        planner: PlannerLike,
        config: EpisodeConfig,
        seed: int,
        planner_name: str,
        preset_name: str,
        seconds: float,
        progress: ProgressCallback | None,
    ) -> None:
        if not (seconds > 0 and math.isfinite(seconds)):
            raise ValueError(f"seconds must be a positive number, got {seconds}")
        self.area, self.truth, self.planner, self.cfg = area, ground_truth, planner, config
        self.seed, self.planner_name, self.preset_name = seed, planner_name, preset_name
        self.t_end = float(seconds)
        self.progress = progress
        self.rng = _Streams.from_seed(seed)
        self.costs = _Costs()
        self.series = _Series()
        cam_cfg = config.camera
        self.camera = DepthCamera(area.vertices, area.triangles, cam_cfg)
        self.mapping = MappingStack(area.bounds_min, area.grid_shape, area.voxel_size,
                                    config.safety_radius_m, config.occupancy)
        self.tsdf = TsdfVolume(cam_cfg.intrinsic_matrix(), cam_cfg.max_range_m, config.tsdf)
        self.drift = OdometryDrift(config.odometry_noise, self.rng.odometry)
        self.world = World(area.vertices, area.triangles, area.start.position, config.limits,
                           config.physics)
        self.yaw = area.start.yaw
        self.recording = RecordingWriter(header={
            "area": area.name, "planner": planner_name, "seed": seed, "preset": preset_name,
            "voxel_size": area.voxel_size, "grid_origin": area.bounds_min.tolist(),
            "grid_shape": list(area.grid_shape), "camera": cam_cfg.model_dump(),
            "pose_rate_hz": config.pose_record_hz,
        })
        # Fixed seeded samples of the truth cloud: small for the snapshots, large for the end.
        self.recall_points = _subsample(ground_truth.surface_points, config.recall_sample_points,
                                        seed)
        self.final_truth = _subsample(ground_truth.surface_points, config.final_recall_points,
                                      seed)
        self.path_length = 0.0
        self.collisions = 0
        self.safety_stops = 0
        self.occupancy_updates = 0
        self.planning_ms: list[float] = []
        self.planned_from = area.start.position.copy()

    def close(self) -> None:
        self.world.close()

    # -- the loop ---------------------------------------------------------------------------

    def run(self) -> EpisodeResult:
        wall0 = time.perf_counter()
        cfg = self.cfg
        self._clear_start_sphere()
        self.frame_period = 1.0 / cfg.camera.rate_hz
        self.frame_index = 0
        self.next_frame = 0.0
        self.next_volume = 0.0
        self.next_recall = cfg.recall_interval_s
        self.next_keyframe = 0.0
        self.next_surface = cfg.surface_snapshot_interval_s
        self.next_pose = 0.0
        ctx = PlannerContext(
            area=self.area.name, bounds_min=self.area.bounds_min.copy(),
            bounds_max=self.area.bounds_max.copy(),
            start=Pose(self.area.start.position.copy(), self.area.start.yaw),
            limits=cfg.limits, safety_radius_m=cfg.safety_radius_m, camera=cfg.camera,
            rng=self.rng.planner,
        )
        self.planner.reset(ctx)
        # Reference state at rest, in the map frame: where the next trajectory starts.
        rest = np.array([*self.area.start.position, self.area.start.yaw])
        hold = TrajectorySample(rest[:3].copy(), np.zeros(3), np.zeros(3), float(rest[3]), 0.0)
        flight = self._startup_spin(rest) if cfg.startup_spin else None
        outcome = PlanOutcome.NONE
        failures = 0
        status, reason = RunStatus.SUCCEEDED, "time limit reached"
        self._on_frame_boundaries(hold)  # the first frame, at t = 0
        while self.world.time < self.t_end - 1e-9:
            if flight is None:
                plan = self._ask(outcome)
                if plan is None:
                    crashed = self.collisions > 0  # while hovering as the planner thought
                    status = RunStatus.CRASHED if crashed else RunStatus.FAILED
                    reason = self.failure
                    break
                if plan.done:
                    reason = f"planner finished: {plan.info.get('reason', 'done')}"
                    break
                # Fly from where odometry says the vehicle is, as the planner saw it: the
                # reference it last held differs by the tracking error and the drift since.
                start = np.array([*self.planned_from, rest[3]])
                flight, outcome = self._fly_plan(plan, start)
                if flight is None:
                    failures += 1
                    if failures >= cfg.max_failed_plans:
                        status = RunStatus.FAILED
                        reason = f"{failures} consecutive plans were {outcome.value}"
                        break
                    if not self._hover(hold, cfg.failed_plan_hover_s):
                        status, reason = RunStatus.CRASHED, "collision while hovering"
                        break
                    continue
                failures = 0
            elif flight.replan_due(self.world.time):
                # A rejected mid-flight plan costs nothing but the call: the checked flight
                # goes on, so it does not count toward `max_failed_plans`.
                flight, outcome, ending = self._replan_in_flight(flight, outcome)
                if ending is not None:
                    status, reason = ending
                    break
            ref = flight.reference(self.world.time)
            if not self._physics_step(ref):
                status, reason = RunStatus.CRASHED, "collision with the scene"
                break
            if flight.finished(self.world.time):
                end = flight.trajectory.sample(flight.stop_after)
                rest = np.array([*end.position, end.yaw])
                hold = TrajectorySample(end.position, np.zeros(3), np.zeros(3), end.yaw, 0.0)
                outcome = PlanOutcome.BLOCKED if flight.braking else PlanOutcome.REACHED
                flight = None
            elif self._path_newly_blocked(flight):
                flight = self._safety_stop(flight)
        simulated_until = self.world.time
        if status is RunStatus.SUCCEEDED:
            self._extend_flat()
        return self._finish(status, reason, simulated_until, time.perf_counter() - wall0)

    def _replan_in_flight(self, flight: _Flight, outcome: PlanOutcome) -> tuple[
        _Flight, PlanOutcome, tuple[RunStatus, str] | None
    ]:
        """Ask the planner mid-flight; the new plan replaces the rest of `flight` only if it
        passes the checks, else `flight` is flown on. Returns the flight to follow, the outcome
        the planner sees next, and (status, reason) if the run ends here."""
        plan = self._ask(PlanOutcome.FLYING, flight)
        if plan is None:
            crashed = self.collisions > 0
            return flight, outcome, (RunStatus.CRASHED if crashed else RunStatus.FAILED,
                                     self.failure)
        if plan.done:
            return flight, outcome, (RunStatus.SUCCEEDED,
                                     f"planner finished: {plan.info.get('reason', 'done')}")
        now = self.world.time
        if plan.keep:
            period = plan.replan_s
            if period is not None and not (math.isfinite(period) and period > 0):
                # A zero period would ask again without the clock moving.
                flight.schedule_replan(now, flight.replan_s)
                return flight, PlanOutcome.INVALID, None
            flight.schedule_replan(now, period)
            return flight, PlanOutcome.FLYING, None
        new, result = self._fly_plan(plan, flight.reference(now))
        if new is None:
            flight.schedule_replan(now, flight.replan_s)
            return flight, result, None
        return new, result, None

    def _ask(self, outcome: PlanOutcome, flight: _Flight | None = None) -> Plan | None:
        pose = self._estimated_pose()
        self.planned_from = pose.position
        obs = Observation(
            time=self.world.time, pose=pose, velocity=self.world.velocity.copy(),
            map=self.mapping.view(), last_outcome=outcome,
        )
        t0 = time.perf_counter()
        try:
            plan = self.planner.plan(obs)
        except Exception as exc:  # a planner bug ends its run, not the process
            self.failure = f"planner raised {type(exc).__name__}: {exc}"
            return None
        elapsed = time.perf_counter() - t0
        self.costs.planner += elapsed
        self.planning_ms.append(1000.0 * elapsed)
        if not isinstance(plan, Plan):
            self.failure = f"planner returned {type(plan).__name__}, not a Plan"
            return None
        if self.cfg.planning_time_charge == "wall" and elapsed > 0:
            # The vehicle hovers while the planner thinks, as in a real-time system; asked
            # mid-flight, it flies on along the current trajectory instead.
            if flight is not None:
                if not self._follow(flight, elapsed):
                    self.failure = "collision while flying"
                    return None
                return plan
            here = self._estimated_pose()
            hold = TrajectorySample(here.position, np.zeros(3), np.zeros(3), here.yaw, 0.0)
            if not self._hover(hold, elapsed):
                self.failure = "collision while hovering"
                return None
        return plan

    def _fly_plan(self, plan: Plan, start: npt.NDArray[np.float64] | TrajectorySample) -> tuple[
        _Flight | None, PlanOutcome
    ]:
        """Check, cut and time-parameterise a plan. `start` is (4,) x, y, z, yaw at rest, or
        the moving reference state of a flight interrupted by `Plan.replan_s`."""
        wps = np.asarray(plan.waypoints, dtype=np.float64)
        if wps.ndim != 2 or wps.shape[1:] != (4,) or len(wps) == 0 or not np.all(np.isfinite(wps)):
            return None, PlanOutcome.INVALID
        inside = np.all((wps[:, :3] >= self.area.bounds_min) &
                        (wps[:, :3] <= self.area.bounds_max), axis=1)
        if not np.all(inside):
            return None, PlanOutcome.INVALID
        replan = plan.replan_s
        if replan is not None and not (math.isfinite(replan) and replan > 0):
            return None, PlanOutcome.INVALID
        view = self.mapping.view()
        moving = isinstance(start, TrajectorySample)
        here = start.position if isinstance(start, TrajectorySample) else start[:3]
        clear = plan_is_clear(view.traversable, view.free, view.origin, view.voxel_size, here,
                              wps[:, :3])
        if clear == 0:
            return None, PlanOutcome.BLOCKED
        wps = wps[:clear]
        try:
            if isinstance(start, TrajectorySample):
                traj = plan_trajectory_from(start, wps, self.cfg.limits)
            else:
                traj = plan_trajectory(start, wps, self.cfg.limits)
        except TrajectoryError:
            return None, PlanOutcome.INVALID
        if moving and not self._first_leg_clear(traj, here):
            return None, PlanOutcome.BLOCKED
        self.recording.plan(self.world.time, wps)
        stop_leg = traj.leg_count - 1
        if plan.horizon_s is not None:
            stop_leg = min(int(np.searchsorted(traj.leg_end_times, plan.horizon_s - 1e-9)),
                           traj.leg_count - 1)
        outcome = PlanOutcome.REACHED if clear == len(plan.waypoints) else PlanOutcome.BLOCKED
        t0 = time.perf_counter()
        checked_on = self.mapping.occupancy.copy_state() if self.cfg.safety_stops else None
        self.costs.checks += time.perf_counter() - t0
        flight = _Flight(traj, self.world.time, float(traj.leg_end_times[stop_leg]), stop_leg,
                         checked_on=checked_on, checked_at_update=self.occupancy_updates)
        flight.schedule_replan(self.world.time, replan)
        return flight, outcome

    def _path_newly_blocked(self, flight: _Flight) -> bool:
        """Whether an occupancy update since the last look found an obstacle the vehicle could
        touch on the rest of the flight's path. Thin surfaces seen from afar can be cleared
        from the map by the rays that pass them and found again nearer, on a path already
        accepted, so the map is not trusted only once, when the plan is checked."""
        # Flights start unguarded (`checked_on` None) when the preset turns safety stops off.
        if flight.checked_on is None or flight.checked_at_update == self.occupancy_updates:
            return False
        flight.checked_at_update = self.occupancy_updates
        t0 = time.perf_counter()
        occ = self.mapping.occupancy
        # Only what the vehicle could touch: a surface in a voxel lies within half the voxel's
        # diagonal of its centre. Stopping for everything within the safety radius stopped
        # flights dozens of times a run for walls 0.4-0.5 m beside the path.
        reach = self.cfg.limits.radius_m + 0.5 * math.sqrt(3.0) * occ.voxel_size
        blocked = path_meets_new_obstacle(occ.state, flight.checked_on, occ.origin,
                                          occ.voxel_size, reach, self._rest_of_path(flight))
        self.costs.checks += time.perf_counter() - t0
        return blocked

    def _rest_of_path(self, flight: _Flight) -> npt.NDArray[np.float64]:
        """(K, 3) the path still to fly: the reference position, then samples of a curved first
        leg (no more than half a voxel apart) and the waypoints ending the straight legs."""
        traj = flight.trajectory
        t = self.world.time - flight.start_time
        leg = min(traj.leg_index(t), flight.stop_leg)
        parts = [flight.reference(self.world.time).position[None]]
        if leg == 0 and traj.curved_first_leg:
            dt = 0.5 * self.area.voxel_size / self.cfg.limits.v_max
            parts.append(traj.positions(float(traj.leg_end_times[0]), dt, start=t))
            leg = 1
        parts.append(traj.waypoints[leg:flight.stop_leg + 1, :3])
        return np.vstack(parts)

    def _safety_stop(self, flight: _Flight) -> _Flight:
        """Brake from the current reference state as fast as the limits allow."""
        try:
            stop = stop_trajectory(flight.reference(self.world.time), self.cfg.limits)
        except TrajectoryError:
            return flight  # no stop from this state: fly on as planned
        self.safety_stops += 1
        self.recording.plan(self.world.time, stop.waypoints)
        return _Flight(stop, self.world.time, stop.duration, 0, braking=True)

    def _first_leg_clear(self, traj: Trajectory, here: npt.NDArray[np.float64]) -> bool:
        """The first leg from a moving state is a curve: check it by its samples, close enough
        (at most half a voxel apart) that the segments between them stand for it. A vehicle
        outside traversable space may cross known free voxels to get back in, as from rest,
        but at speed only within one safety radius of where it is."""
        view = self.mapping.view()
        dt = 0.5 * view.voxel_size / self.cfg.limits.v_max
        samples = np.vstack([here[None], traj.positions(float(traj.leg_end_times[0]), dt)])
        idx = view.world_to_index(samples)
        if not np.all(view.in_bounds(idx)):
            return False
        entered = np.flatnonzero(view.traversable[idx[:, 0], idx[:, 1], idx[:, 2]])
        if len(entered) == 0:
            return False
        first = int(entered[0])
        escape = float(np.sum(np.linalg.norm(np.diff(samples[: first + 1], axis=0), axis=1)))
        if escape > self.cfg.safety_radius_m:
            return False
        return plan_is_clear(view.traversable, view.free, view.origin, view.voxel_size, here,
                             samples[1:]) == len(samples) - 1

    def _startup_spin(self, rest: npt.NDArray[np.float64]) -> _Flight:
        """One turn in place before the first plan, so that every planner starts from the same
        all-round view instead of a single frustum."""
        turns = rest[None].repeat(4, axis=0)
        turns[:, 3] = rest[3] + np.pi / 2.0 * np.arange(1, 5)
        traj = plan_trajectory(rest, turns, self.cfg.limits)
        return _Flight(traj, self.world.time, traj.duration, traj.leg_count - 1)

    def _follow(self, flight: _Flight, seconds: float) -> bool:
        """Fly on along `flight` for `seconds` (holding its end if it ends first)."""
        end = self.world.time + seconds
        while self.world.time < min(end, self.t_end) - 1e-9:
            if not self._physics_step(flight.reference(self.world.time)):
                return False
        return True

    def _hover(self, hold: TrajectorySample, seconds: float) -> bool:
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
        shifted = TrajectorySample(ref.position - self.drift.offset, ref.velocity,
                                   ref.acceleration, ref.yaw, ref.yaw_rate)
        contact = self.world.step(shifted)
        self.yaw = ref.yaw
        self.path_length += float(np.linalg.norm(self.world.position - before))
        self.costs.physics += time.perf_counter() - t0
        if contact is not None:
            self.collisions += 1
            return False
        self._on_frame_boundaries(ref)
        return True

    def _on_frame_boundaries(self, ref: TrajectorySample) -> None:
        now = self.world.time
        while self.next_frame <= now + 1e-9:
            self._camera_frame(self.next_frame)
            self.next_frame += self.frame_period
        if now >= self.next_pose - 1e-9:
            self.recording.pose(now, self.world.position, self.yaw)
            self.next_pose += 1.0 / self.cfg.pose_record_hz

    def _camera_frame(self, stamp: float) -> None:
        cfg, costs = self.cfg, self.costs
        i = self.frame_index
        self.frame_index += 1
        self.drift.step()
        fuse_occ = i % cfg.occupancy_every_n_frames == 0
        fuse_tsdf = i % cfg.tsdf_every_n_frames == 0
        if fuse_occ or fuse_tsdf:
            costs.frames += 1
            t0 = time.perf_counter()
            true_pose = Pose(self.world.position.copy(), self.yaw)
            # A frame only the occupancy map uses is rendered at its pixel stride.
            stride = 1 if fuse_tsdf else cfg.occupancy_pixel_stride
            frame = self.camera.render(true_pose, stamp, stride)
            depth = add_depth_noise(frame.depth, cfg.depth_noise, self.rng.depth)
            estimate = self.drift.estimate(true_pose)
            t1 = time.perf_counter()
            costs.render += t1 - t0
            if fuse_occ or fuse_tsdf:
                s = cfg.occupancy_pixel_stride
                occ_depth = depth[::s, ::s] if stride == 1 and s > 1 else depth
                ends, hit = self.camera.back_project(occ_depth, estimate, s)
                if fuse_occ:
                    self.mapping.occupancy.integrate(estimate.position, ends, hit)
                    self.occupancy_updates += 1
                if fuse_tsdf:
                    # The surface layers count the frames the TSDF fuses (`sim/surface.py`).
                    self.mapping.surface.observe(estimate.position, ends[hit])
            t2 = time.perf_counter()
            costs.occupancy += t2 - t1
            if fuse_tsdf:
                try:
                    self.tsdf.integrate(depth, estimate)
                except RuntimeError as exc:
                    # A frame with no return within range (open space) has nothing to fuse,
                    # and Open3D refuses it instead of doing nothing.
                    if "No block is touched" not in str(exc):
                        raise
            costs.tsdf += time.perf_counter() - t2
        t3 = time.perf_counter()
        self._sample_metrics(stamp)
        costs.metrics += time.perf_counter() - t3

    def _sample_metrics(self, stamp: float) -> None:
        cfg = self.cfg
        if stamp >= self.next_volume - 1e-9:
            volume = self.mapping.occupancy.explored_volume_m3
            self.series.volume_times.append(round(stamp, 6))
            self.series.volume.append(volume)
            self.next_volume += cfg.volume_interval_s
            if self.progress is not None:
                self.progress(stamp, volume)
        if stamp >= self.next_keyframe - 1e-9:
            self.recording.map_keyframe(stamp, self.mapping.occupancy.state)
            self.next_keyframe += cfg.keyframe_interval_s
        if stamp >= self.next_recall - 1e-9:
            self.series.recall_times.append(round(stamp, 6))
            self.series.recall.append(self._recall_now())
            self.next_recall += cfg.recall_interval_s
        if stamp >= self.next_surface - 1e-9:
            self.recording.surface(stamp, self.tsdf.surface_points(), cfg.surface_snapshot_voxel_m)
            self.next_surface += cfg.surface_snapshot_interval_s

    def _recall_now(self) -> float:
        sdf, weight = self.tsdf.sdf_at(self.recall_points)
        return sdf_surface_recall(sdf, weight, self.cfg.surface_tau_m,
                                  self.cfg.tsdf.weight_threshold)

    def _extend_flat(self) -> None:
        """After an early finish the map no longer changes: the curve stays flat to the end."""
        last_volume = self.mapping.occupancy.explored_volume_m3
        last_recall = self.series.recall[-1] if self.series.recall else None
        while self.next_volume <= self.t_end + 1e-9:
            self.series.volume_times.append(round(self.next_volume, 6))
            self.series.volume.append(last_volume)
            self.next_volume += self.cfg.volume_interval_s
        if last_recall is None:
            last_recall = self._recall_now()
        while self.next_recall <= self.t_end + 1e-9:
            self.series.recall_times.append(round(self.next_recall, 6))
            self.series.recall.append(last_recall)
            self.next_recall += self.cfg.recall_interval_s

    def _clear_start_sphere(self) -> None:
        """The space around the start is known free, as a vehicle is placed in a clear spot
        before take-off: rays from the centre carve a sphere of `start_free_radius_m`, never
        closer than a voxel to a real surface. Without it the level camera's blind cones above
        and below the vehicle would leave no traversable way out of the start."""
        clearance = self.camera.distance_to_surface(self.area.start.position)
        r = min(self.cfg.start_free_radius_m, clearance - self.area.voxel_size)
        if r <= 0:
            return
        n = 400
        k = np.arange(n) + 0.5
        phi = np.arccos(1.0 - 2.0 * k / n)
        theta = np.pi * (1.0 + 5**0.5) * k
        dirs = np.stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], 1)
        centre = self.area.start.position
        self.mapping.occupancy.integrate(centre, centre + r * dirs, np.zeros(n, dtype=bool))

    def _estimated_pose(self) -> Pose:
        return self.drift.estimate(Pose(self.world.position.copy(), self.yaw))

    def _finish(self, status: RunStatus, reason: str, simulated_until: float,
                wall: float) -> EpisodeResult:
        t0 = time.perf_counter()
        vertices, triangles = self.tsdf.mesh()
        scores = surface_scores(vertices, self.final_truth, self.cfg.surface_tau_m,
                                self.camera.distance_to_surface_many)
        self.costs.metrics += time.perf_counter() - t0
        explored = self.mapping.occupancy.explored_volume_m3
        observable = self.truth.observable_volume_m3
        # Coverage counts only what could be observed: noise also marks voxels inside walls.
        known = self.mapping.occupancy.state != 0
        explored_observable = float(np.count_nonzero(known & self.truth.observable)) * \
            self.area.voxel_size**3
        return EpisodeResult(
            area=self.area.name, planner=self.planner_name, seed=self.seed,
            preset=self.preset_name, status=status, reason=reason,
            sim_seconds=self.t_end if status is RunStatus.SUCCEEDED else simulated_until,
            simulated_until=simulated_until, wall_seconds=wall + time.perf_counter() - t0,
            explored_volume_m3=explored, observable_volume_m3=observable,
            coverage=coverage(explored_observable, observable), collisions=self.collisions,
            path_length_m=self.path_length, iterations=len(self.planning_ms),
            planning_times_ms=np.array(self.planning_ms), surface=scores,
            volume_times=np.array(self.series.volume_times),
            volume_m3=np.array(self.series.volume),
            recall_times=np.array(self.series.recall_times),
            recall=np.array(self.series.recall),
            frame_costs_ms=self.costs.per_frame_ms(),
            mesh_vertices=vertices, mesh_triangles=triangles, safety_stops=self.safety_stops,
        )
