"""The Gymnasium environments: the checker, determinism, vector environments, and a policy run
as a planner flying exactly as it flies in the environment."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from types import ModuleType

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import flybo.envs  # noqa: F401 - registers the environments
from areas import load_area, load_ground_truth
from planners.policy import PolicyConfig, PolicyPlanner
from sim.config import preset
from sim.episode import run_episode

KEYS = ("pose", "occupancy", "frontier")


def _example(name: str) -> ModuleType:
    path = Path(__file__).resolve().parents[1] / "examples" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(f"examples_{name}", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_the_environment_passes_gymnasiums_checker() -> None:
    env = gym.make("flybo/Explore-v1", preset_name="exact", seconds=20.0)
    check_env(env.unwrapped, skip_render_check=False)
    env.close()


def test_same_seed_same_episode() -> None:
    env = gym.make("flybo/Explore-v1", preset_name="default", seconds=20.0)
    first, info = env.reset(seed=5)
    again, info_again = env.reset(seed=5)
    assert info["episode_seed"] == info_again["episode_seed"]
    for key in first:
        np.testing.assert_array_equal(first[key], again[key])
    assert env.observation_space.contains(first)
    obs, reward, terminated, _, step_info = env.step(np.zeros(4, dtype=np.float32))
    assert env.observation_space.contains(obs)
    assert isinstance(reward, float) and not terminated
    assert step_info["time"] > info["time"]
    env.close()


def test_an_episode_ends_with_the_benchmarks_metrics() -> None:
    env = gym.make("flybo/Explore-v1", preset_name="exact", seconds=15.0, observation=KEYS)
    env.reset(seed=0)
    done, info = False, {}
    while not done:
        _, _, terminated, truncated, info = env.step(np.array([0.3, 0.0, 0.0, 0.2],
                                                              dtype=np.float32))
        done = terminated or truncated
    assert truncated and info["status"] == "succeeded"
    assert 0 < info["metrics"]["coverage"] < 1
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(4, dtype=np.float32))
    env.close()


def test_every_built_in_area_can_be_drawn() -> None:
    env = gym.make("flybo/ExploreAll-v1", preset_name="exact", seconds=5.0, observation=KEYS)
    seen = {env.reset(seed=s)[1]["area"] for s in range(6)}
    assert len(seen) >= 2
    env.close()


def test_bad_arguments_are_refused() -> None:
    with pytest.raises(ValueError, match="unknown observation keys"):
        gym.make("flybo/Explore-v1", observation=("pose", "lidar"))


def test_two_environments_run_in_subprocesses() -> None:
    envs = gym.vector.AsyncVectorEnv([
        lambda: gym.make("flybo/Explore-v1", preset_name="exact", seconds=12.0,
                         observation=KEYS) for _ in range(2)])
    obs, _ = envs.reset(seed=[0, 1])
    assert obs["pose"].shape == (2, 7)
    for _ in range(3):
        obs, reward, _, _, _ = envs.step(np.zeros((2, 4), dtype=np.float32))
    assert reward.shape == (2,)
    envs.close()


def test_the_frontier_agent_flies_the_same_as_a_planner() -> None:
    agent_module = _example("frontier_agent")
    env = gym.make("flybo/Explore-v1", preset_name="exact", seconds=40.0, observation=KEYS)
    obs, info = env.reset(seed=3)
    episode_seed = info["episode_seed"]
    agent = agent_module.FrontierAgent(0.1)
    done = False
    while not done:
        obs, _, terminated, truncated, info = env.step(agent(obs))
        done = terminated or truncated
    env.close()
    area = load_area("maze")
    planner = PolicyPlanner(PolicyConfig(keys=KEYS), policy=agent_module.FrontierAgent(0.1))
    result = run_episode(area, load_ground_truth(area), planner, preset("exact"),
                         episode_seed, seconds=40.0)
    assert result.metrics == info["metrics"]
