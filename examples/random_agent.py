"""A random agent on `flybo/Explore-v1`: uniform actions until the episode ends.

    .venv/bin/python examples/random_agent.py [--area maze] [--seconds 60] [--seed 0]
"""

from __future__ import annotations

import argparse

import gymnasium as gym

import flybo.envs  # noqa: F401 - registers the environments


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--area", default="maze")
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    env = gym.make("flybo/Explore-v1", area=args.area, seconds=args.seconds)
    env.action_space.seed(args.seed)
    env.reset(seed=args.seed)
    total, steps, done = 0.0, 0, False
    while not done:
        _, reward, terminated, truncated, info = env.step(env.action_space.sample())
        total += float(reward)
        steps += 1
        done = terminated or truncated
    print(f"{steps} steps, return {total:.2f}, coverage {info['coverage']:.3f}, "
          f"{info.get('reason')}")
    env.close()


if __name__ == "__main__":
    main()
