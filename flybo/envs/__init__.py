"""Gymnasium environments on the benchmark's scenes, sensors and metrics.

Importing this package registers (`docs/gymnasium.md`):

- ``flybo/Explore-v1``: one area (kwarg ``area``, default ``maze``);
- ``flybo/ExploreAll-v1``: a built-in area drawn per reset, for training.
"""

from __future__ import annotations

from typing import Any

from gymnasium.envs.registration import register, registry

from flybo.envs.explore import ExploreEnv

__all__ = ["ExploreEnv"]

_ENVS: dict[str, dict[str, Any]] = {
    "flybo/Explore-v1": {"area": "maze"},
    "flybo/ExploreAll-v1": {"area": None},
}

for _id, _kwargs in _ENVS.items():
    if _id not in registry:
        register(id=_id, entry_point="flybo.envs.explore:ExploreEnv", kwargs=_kwargs,
                 disable_env_checker=False)
