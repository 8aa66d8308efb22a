"""The episode: one planner exploring one area, from start to plateau.

`run_episode` is the single entry point used by the CLI and the workers. The episode is made of
parts with one job each:

- the loop (`sim.episode_loop`): simulated time, physics steps toward the reference, when to
  ask the planner (at rest, or mid-flight when the plan asked for it with `Plan.replan_s`) and
  what its thinking costs on the simulated clock;
- sensing and fusion (`sim.sensing`): camera frames, noise, occupancy map and TSDF;
- the plan check (`sim.plan_check`) and the safety monitor (`sim.safety_monitor`): a plan is
  flown only if its path is traversable; while it is flown, every occupancy update checks the
  rest of its path, and an obstacle found since, close enough for the vehicle to touch it,
  makes the vehicle brake to a stop (a safety stop) and the planner is asked again with BLOCKED;
- recording (`sim.episode_recorder`) and the measures (`sim.measures`), which define the metrics.

The run ends at the time limit, when the planner says done (the rest of the curve is then flat
and not simulated), on a collision (`crashed`) or on a planner failure.
"""

from __future__ import annotations

from pathlib import Path

from areas.area import Area, GroundTruth
from sim import reference_speed
from sim.config import EpisodeConfig
from sim.episode_loop import Ending, EpisodeLoop, PlanReply, PlanRequest
from sim.interface import Observation, PlannerContext, PlannerLike
from sim.measures.base import ProgressCallback
from sim.planning_charge import PlanningCharge
from sim.result import EpisodeResult, RunStatus

__all__ = ["EpisodeStepper", "ProgressCallback", "run_episode"]


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
    speed_factor: float | None = None,
    platform_errors: tuple[type[BaseException], ...] = (),
) -> EpisodeResult:
    """Run one exploration episode and measure it.

    Args:
        seconds: simulated time limit; the area's plateau time when None.
        recording_path: where to write the run recording (`.npz`), if anywhere.
        progress: called about once per simulated second with (time, explored volume m³).
        speed_factor: this machine's speed over the reference's, for the 'cpu' planning
            charge; measured once per process when None (`sim.reference_speed`).
        platform_errors: exceptions that are the platform's, not the planner's (a worker's
            time limit): raised from a `plan` call they end the run by propagating, instead of
            being recorded as a planner failure.
    """
    if speed_factor is None and config.planning_time_charge == "cpu":
        speed_factor = reference_speed.speed_factor()
    charge = PlanningCharge(config.planning_time_charge, speed_factor or 1.0, planner)
    loop = EpisodeLoop(area, ground_truth, config, seed, planner_name, preset_name,
                       seconds if seconds is not None else area.plateau_s, progress)
    try:
        result = loop.run_with(planner, charge, platform_errors)
    finally:
        loop.close()
    try:
        if recording_path is not None:
            loop.recorder.save(recording_path)
    finally:
        loop.recorder.close()
    return result


class EpisodeStepper:
    """An episode driven from outside, one plan at a time: `start` gives the planner's context
    and the first observation, each `step` flies a plan until the next one is needed (None
    when the run has ended), `result` scores the run. The loop is the one `run_episode` flies;
    nothing is charged for thinking but what `step` is told (`charge_s`)."""

    def __init__(self, area: Area, ground_truth: GroundTruth, config: EpisodeConfig, seed: int,
                 *, planner_name: str = "agent", preset_name: str = "custom",
                 seconds: float | None = None) -> None:
        self.loop = EpisodeLoop(area, ground_truth, config, seed, planner_name, preset_name,
                                seconds if seconds is not None else area.plateau_s, None)
        self._steps = self.loop.steps()
        self._ending: Ending | None = None
        self._result: EpisodeResult | None = None

    def start(self) -> tuple[PlannerContext, Observation | None]:
        context = self.loop.begin()
        return context, self._advance(None)

    def step(self, plan: object, charge_s: float = 0.0) -> Observation | None:
        """Fly `plan` (checked as any planner's) until the next plan is needed."""
        if self._ending is not None:
            raise RuntimeError("the episode has ended")
        return self._advance(PlanReply(plan, 0.0, charge_s))

    def _advance(self, reply: PlanReply | None) -> Observation | None:
        try:
            request: PlanRequest = (next(self._steps) if reply is None
                                    else self._steps.send(reply))
        except StopIteration as stop:
            self._ending = stop.value
            return None
        return request.observation

    def stop(self, reason: str) -> None:
        """End the run here, as a planner that says it is done (the curves stay flat)."""
        if self._ending is None:
            self._steps.close()
            self._ending = Ending(RunStatus.SUCCEEDED, f"planner finished: {reason}")

    @property
    def ended(self) -> bool:
        return self._ending is not None

    def result(self) -> EpisodeResult:
        """The run's result, once it has ended."""
        if self._ending is None:
            raise RuntimeError("the episode has not ended")
        if self._result is None:
            self._result = self.loop.finish(self._ending)
        return self._result

    def close(self) -> None:
        self._steps.close()
        self.loop.close()
        self.loop.recorder.close()
