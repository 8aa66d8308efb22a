"""The exploration environment: an agent flies the benchmark's vehicle, one action per step.

Each step turns the action into a plan (`planners.policy.action_to_plan`), which the
framework checks and flies exactly as it flies any planner's, until the next plan is needed.

Reward: the explored observable volume the step added (m³), minus ``time_cost`` per simulated
second the step took, minus ``collision_penalty`` on a collision. ``terminated`` on a collision,
on a failed run (``max_failed_plans`` unusable actions in a row) or when the area is finished
(coverage at least ``finish_coverage``); ``truncated`` at the time limit (the area's plateau
time unless ``seconds``). ``info`` holds the simulated time, the coverage, the last outcome and,
at the end of an episode, the benchmark's metrics (`result.json`'s ``metrics``). Thinking is not
charged to the simulated clock (a trained policy's cost belongs to its planner submission).
"""

from __future__ import annotations

from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
import numpy.typing as npt
from gymnasium import spaces

from areas import area_names, load_area
from areas.area import Area, GroundTruth
from areas.build_lock import load_ground_truth_once
from planners.policy import ObservationKey, PolicyConfig, action_to_plan, observe
from sim.config import EpisodeConfig, preset
from sim.episode import EpisodeStepper
from sim.interface import Observation, PlannerContext, PlanOutcome
from sim.occupancy import VoxelState
from sim.result import RunStatus

EnvObservation = dict[str, Any]
# Positions (m), yaw (rad) and velocities (m/s) stay far inside this in any area.
_POSE_BOUND = 1.0e4


class ExploreEnv(gym.Env[EnvObservation, npt.NDArray[np.float32]]):
    """`flybo/Explore-v1` (see the module docstring)."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 4}  # noqa: RUF012 - Gymnasium's

    def __init__(self, area: str | None = "maze", preset_name: str = "default",
                 action: str = "waypoint",
                 observation: tuple[str, ...] = ("depth", "pose", "occupancy", "frontier"),
                 crop_xy: int = 64, crop_z: int = 16, max_step_m: float = 3.0,
                 step_s: float = 1.0, seconds: float | None = None, time_cost: float = 0.01,
                 collision_penalty: float = 10.0, finish_coverage: float = 0.99,
                 render_mode: str | None = None) -> None:
        unknown = set(observation) - {"depth", "pose", "occupancy", "frontier"}
        if unknown:
            raise ValueError(f"unknown observation keys {sorted(unknown)}; "
                             "known: depth, pose, occupancy, frontier")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        self.areas = [area] if area is not None else area_names()
        self.config: EpisodeConfig = preset(preset_name)
        self.preset_name = preset_name
        keys: tuple[ObservationKey, ...] = tuple(
            k for k in ("pose", "occupancy", "frontier") if k in observation)
        self.policy_cfg = PolicyConfig(keys=keys, crop_xy=crop_xy, crop_z=crop_z,
                                       action=action,
                                       max_step_m=max_step_m, step_s=step_s)
        self.with_depth = "depth" in observation
        self.seconds, self.time_cost = seconds, time_cost
        self.collision_penalty, self.finish_coverage = collision_penalty, finish_coverage
        self.render_mode = render_mode
        self.action_space = spaces.Box(-1.0, 1.0, shape=(4,), dtype=np.float32)
        self.observation_space = spaces.Dict(self._spaces())
        self._scenes: dict[str, tuple[Area, GroundTruth]] = {}
        self._stepper: EpisodeStepper | None = None
        self._ctx: PlannerContext | None = None
        self._obs: Observation | None = None
        self._last: EnvObservation = {}

    def _spaces(self) -> dict[str, spaces.Space[Any]]:
        cam, c = self.config.camera, self.policy_cfg
        out: dict[str, spaces.Space[Any]] = {}
        if self.with_depth:
            # Metres; 0 where a pixel has no return within range.
            out["depth"] = spaces.Box(0.0, float(cam.max_range_m), shape=(cam.height, cam.width),
                                      dtype=np.float32)
        if "pose" in c.keys:
            out["pose"] = spaces.Box(-_POSE_BOUND, _POSE_BOUND, shape=(7,), dtype=np.float32)
        crop = (c.crop_xy, c.crop_xy, c.crop_z)
        if "occupancy" in c.keys:
            out["occupancy"] = spaces.Box(0, int(VoxelState.OCCUPIED), shape=crop, dtype=np.uint8)
        if "frontier" in c.keys:
            out["frontier"] = spaces.Box(0, 1, shape=crop, dtype=np.uint8)
        return out

    def _scene(self, name: str) -> tuple[Area, GroundTruth]:
        if name not in self._scenes:
            area = load_area(name)
            self._scenes[name] = (area, load_ground_truth_once(area))
        return self._scenes[name]

    # -- the Gymnasium API -------------------------------------------------------------------

    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[EnvObservation, dict[str, Any]]:
        super().reset(seed=seed)
        self._close_episode()
        name = self.areas[int(self.np_random.integers(len(self.areas)))]
        area, truth = self._scene(name)
        self.area, self.truth = area, truth
        episode_seed = int(self.np_random.integers(2**31 - 1))
        self._stepper = EpisodeStepper(area, truth, self.config, episode_seed,
                                       planner_name="agent", preset_name=self.preset_name,
                                       seconds=self.seconds)
        self._ctx, self._obs = self._stepper.start()
        self._explored = self._explored_observable()
        self._last = self._observation()
        return self._last, {"area": name, "episode_seed": episode_seed, "time": self._time(),
                            "coverage": self._coverage()}

    def step(self, action: npt.NDArray[np.float32]) -> tuple[
        EnvObservation, SupportsFloat, bool, bool, dict[str, Any]
    ]:
        if self._stepper is None or self._ctx is None:
            raise RuntimeError("call reset() before step()")
        if self._obs is None:
            raise RuntimeError("the episode has ended: call reset()")
        t0 = self._time()
        plan = action_to_plan(action, self._obs, self._ctx, self.policy_cfg)
        self._obs = self._stepper.step(plan)
        explored = self._explored_observable()
        reward = explored - self._explored - self.time_cost * (self._time() - t0)
        self._explored = explored
        info: dict[str, Any] = {"time": self._time(), "coverage": self._coverage()}
        terminated = truncated = False
        if self._obs is None:
            result = self._stepper.result()
            info["metrics"] = dict(result.metrics)
            info["status"], info["reason"] = result.status.value, result.reason
            if result.status is RunStatus.CRASHED:
                reward -= self.collision_penalty
            terminated = result.status is not RunStatus.SUCCEEDED or \
                result.sim_seconds > result.simulated_until + 1e-9
            truncated = not terminated
        else:
            info["last_outcome"] = self._obs.last_outcome.value
            if info["coverage"] >= self.finish_coverage:
                terminated = True
                assert self._stepper is not None
                self._stepper.stop("area finished")
                info["metrics"] = dict(self._stepper.result().metrics)
                self._last = self._observation()
                self._obs = None
                return self._last, float(reward), terminated, truncated, info
        self._last = self._observation()
        return self._last, float(reward), terminated, truncated, info

    def render(self) -> npt.NDArray[np.uint8] | None:
        """The last full-resolution depth frame as an RGB image (near is bright)."""
        if self.render_mode != "rgb_array" or self._stepper is None:
            return None
        depth = self._stepper.loop.sensing.last_depth
        rng = self.config.camera.max_range_m
        level = np.where(np.isfinite(depth), 1.0 - np.clip(depth / rng, 0.0, 1.0), 0.0)
        grey = (255 * level).astype(np.uint8)
        return np.repeat(grey[:, :, None], 3, axis=2)

    def close(self) -> None:
        self._close_episode()

    # -- helpers -----------------------------------------------------------------------------

    def _close_episode(self) -> None:
        if self._stepper is not None:
            self._stepper.close()
            self._stepper = None

    def _time(self) -> float:
        assert self._stepper is not None
        return float(self._stepper.loop.world.time)

    def _explored_observable(self) -> float:
        assert self._stepper is not None
        known = self._stepper.loop.sensing.mapping.occupancy.state != 0
        return float(np.count_nonzero(known & self.truth.observable)) * self.area.voxel_size**3

    def _coverage(self) -> float:
        observable = self.truth.observable_volume_m3
        return self._explored / observable if observable > 0 else 0.0

    def _observation(self) -> EnvObservation:
        out: EnvObservation = {}
        if self.with_depth:
            assert self._stepper is not None
            depth = self._stepper.loop.sensing.last_depth
            rng = self.config.camera.max_range_m
            valid = np.isfinite(depth) & (depth > 0) & (depth <= rng)
            out["depth"] = np.where(valid, depth, 0.0).astype(np.float32)
        assert self._stepper is not None
        seen = self._obs if self._obs is not None else \
            self._stepper.loop.observation(PlanOutcome.NONE)  # the episode has ended
        out.update(observe(seen, self.policy_cfg))
        return out
