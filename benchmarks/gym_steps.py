"""Environment steps per second: one `flybo/Explore-v1` alone, and two under Gymnasium's
`AsyncVectorEnv` (one process each), with the waypoint action. Target: two at least 1.8x one.

    .venv/bin/python benchmarks/gym_steps.py [--steps 200] [--area maze]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import gymnasium as gym
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import flybo.envs  # noqa: F401 - registers the environments
from benchmarks.common import print_table, write_json

KEYS = ("depth", "pose", "occupancy", "frontier")


def _make(area: str) -> gym.Env:  # type: ignore[type-arg]
    return gym.make("flybo/Explore-v1", area=area, preset_name="default", observation=KEYS)


def _action(rng: np.random.Generator, n: int) -> np.ndarray:
    # Short level hops and turns: most are flyable, as a learning agent's would become.
    a = rng.uniform(-1.0, 1.0, size=(n, 4)).astype(np.float32)
    a[:, :3] *= 0.3
    a[:, 2] = 0.0
    return a


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--area", default="maze")
    args = parser.parse_args()
    # One action sequence, flown by the single environment and by both vectorised ones from the
    # same seed: a step's cost depends on the hop it flies, so all three do the same work.
    actions = _action(np.random.default_rng(0), args.steps)
    env = _make(args.area)
    env.reset(seed=0)
    t0 = time.perf_counter()
    for action in actions:
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset(seed=0)
    one = args.steps / (time.perf_counter() - t0)
    env.close()
    envs = gym.vector.AsyncVectorEnv([lambda: _make(args.area) for _ in range(2)])
    envs.reset(seed=[0, 0])
    t0 = time.perf_counter()
    for action in actions:
        envs.step(np.stack([action, action]))
    two = 2 * args.steps / (time.perf_counter() - t0)
    envs.close()
    print_table(f"Environment steps per second ({args.area}, waypoint action, default preset)",
                ["environments", "steps/s", "vs one"],
                [["1", f"{one:.1f}", "1.00"], ["2 (AsyncVectorEnv)", f"{two:.1f}",
                                               f"{two / one:.2f}"]])
    print(f"\nwritten to {write_json('gym_steps', {'one': one, 'two': two, 'ratio': two / one})}")


if __name__ == "__main__":
    main()
