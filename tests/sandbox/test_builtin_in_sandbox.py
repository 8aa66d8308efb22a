"""A built-in planner gives the same run in the sandbox as in process (planning time not
charged), and the map it sees through shared memory is the runner's map."""

from __future__ import annotations

import numpy as np

from areas import load_area, load_ground_truth
from planners.registry import make
from sim.config import preset
from sim.episode import run_episode
from worker.sandbox.proxy import SandboxedPlanner


def test_classic_in_the_sandbox_matches_in_process() -> None:
    area = load_area("maze")
    truth = load_ground_truth(area)
    config = preset("exact")
    direct = run_episode(area, truth, make("classic"), config, 2, seconds=40.0)
    with SandboxedPlanner(builtin="classic") as planner:
        boxed = run_episode(area, truth, planner, config, 2, seconds=40.0)
    assert boxed.status == direct.status
    assert boxed.iterations == direct.iterations > 3
    np.testing.assert_array_equal(boxed.volume_m3, direct.volume_m3)
    assert boxed.path_length_m == direct.path_length_m
