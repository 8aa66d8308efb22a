"""A frontier-heuristic agent on `flybo/Explore-v1`: it flies level toward the nearest frontier
voxel in its crop that it can stop short of in known free space; with none in reach, toward the
clear free voxel of its crop farthest from where it has been.

    .venv/bin/python examples/frontier_agent.py [--area maze] [--seconds 120] [--seed 0]

The same agent runs as a planner through `planners.policy.PolicyPlanner` (see
`docs/gymnasium.md`).
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping

import numpy as np
import numpy.typing as npt

STAND_OFF_M = 0.6  # about the framework's safety radius (vehicle radius plus margin)
CLEAR_VOXELS = 3  # known free space demanded around a stop, voxels each way


class FrontierAgent:
    """Observation dict (``pose``, ``occupancy``, ``frontier``) -> waypoint action."""

    def __init__(self, voxel_size: float, max_step_m: float = 3.0) -> None:
        self.voxel_size, self.max_step_m = voxel_size, max_step_m
        self.reset()

    def reset(self) -> None:
        self.visited: list[npt.NDArray[np.float64]] = []
        self.tried: list[npt.NDArray[np.float64]] = []
        self.last_target: npt.NDArray[np.float64] | None = None

    def __call__(self, obs: Mapping[str, npt.NDArray[np.generic]]) -> npt.NDArray[np.float32]:
        pose = np.asarray(obs["pose"], dtype=np.float64)
        here = pose[:3]
        if self.last_target is not None:
            self.tried.append(self.last_target)  # reached or refused: look elsewhere next
        self.visited.append(here.copy())
        occupancy = np.asarray(obs["occupancy"])
        centre = np.array(occupancy.shape) // 2
        step = self._frontier_step(np.asarray(obs["frontier"]), occupancy, centre, here)
        if step is None:
            step = self._open_step(occupancy, centre, here)
        action = np.zeros(4, dtype=np.float32)
        if step is None:
            self.last_target = None
            action[3] = 0.5  # nothing in reach: turn and look
            return action
        self.last_target = here + step
        length = float(np.linalg.norm(step))
        if length > self.max_step_m:
            step = step * (self.max_step_m / length)
        action[:3] = step / self.max_step_m
        turn = float(np.arctan2(step[1], step[0]) - pose[3]) / np.pi
        action[3] = (turn + 1.0) % 2.0 - 1.0
        return np.clip(action, -1.0, 1.0)

    def _usable(self, step: npt.NDArray[np.float64], occupancy: npt.NDArray[np.generic],
                centre: npt.NDArray[np.int64], here: npt.NDArray[np.float64]) -> bool:
        cell = centre + np.round(step / self.voxel_size).astype(int)
        target = here + step
        return _clear_around(occupancy, cell, CLEAR_VOXELS) and all(
            np.linalg.norm(target - t) > 0.5 for t in self.tried)

    def _frontier_step(self, frontier: npt.NDArray[np.generic],
                       occupancy: npt.NDArray[np.generic], centre: npt.NDArray[np.int64],
                       here: npt.NDArray[np.float64]) -> npt.NDArray[np.float64] | None:
        offsets = (np.argwhere(frontier > 0) - centre) * self.voxel_size
        offsets[:, 2] = 0.0  # fly level, at the height the camera sees best
        distance = np.linalg.norm(offsets, axis=1)
        for i in np.argsort(distance, kind="stable"):
            if distance[i] < 2 * STAND_OFF_M:
                continue
            step = offsets[i] * (1.0 - STAND_OFF_M / distance[i])
            if self._usable(step, occupancy, centre, here):
                return step
        return None

    def _open_step(self, occupancy: npt.NDArray[np.generic], centre: npt.NDArray[np.int64],
                   here: npt.NDArray[np.float64]) -> npt.NDArray[np.float64] | None:
        level = occupancy[:, :, centre[2]]
        cells = np.argwhere(level == 1)
        offsets = np.column_stack([(cells - centre[:2]) * self.voxel_size,
                                   np.zeros(len(cells))])
        far = np.linalg.norm(offsets, axis=1) >= 1.0
        offsets = offsets[far]
        if len(offsets) == 0:
            return None
        visited = np.array(self.visited)
        novelty = np.min(np.linalg.norm((here + offsets)[:, None] - visited[None], axis=2),
                         axis=1)
        for i in np.argsort(-novelty, kind="stable")[:200]:
            if self._usable(offsets[i], occupancy, centre, here):
                return offsets[i]
        return None


def _clear_around(occupancy: npt.NDArray[np.generic], cell: npt.NDArray[np.int64],
                  r: int) -> bool:
    lo, hi = cell - r, cell + r + 1
    if np.any(lo < 0) or np.any(hi > occupancy.shape):
        return False
    return bool(np.all(occupancy[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]] == 1))


def main() -> None:
    import gymnasium as gym

    import flybo.envs  # noqa: F401 - registers the environments

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--area", default="maze")
    parser.add_argument("--seconds", type=float, default=120.0)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    env = gym.make("flybo/Explore-v1", area=args.area, seconds=args.seconds,
                   observation=("pose", "occupancy", "frontier"))
    obs, info = env.reset(seed=args.seed)
    agent = FrontierAgent(env.unwrapped.area.voxel_size)  # type: ignore[attr-defined]
    total, done = 0.0, False
    while not done:
        obs, reward, terminated, truncated, info = env.step(agent(obs))
        total += float(reward)
        done = terminated or truncated
    print(f"return {total:.1f}, coverage {info['coverage']:.3f}, {info.get('reason')}")
    env.close()


if __name__ == "__main__":
    main()
