"""An episode driven one plan at a time flies exactly as `run_episode` does."""

from __future__ import annotations

import pytest

from areas import load_area, load_ground_truth
from planners.registry import make
from sim.config import preset
from sim.episode import EpisodeStepper, run_episode
from tests.sim.episode_fingerprints import canonical_result


def test_a_stepped_episode_is_the_same_episode() -> None:
    area = load_area("maze")
    truth = load_ground_truth(area)
    cfg = preset("exact")
    direct = run_episode(area, truth, make("classic"), cfg, 4, planner_name="classic-v1",
                         preset_name="exact", seconds=25.0)
    stepper = EpisodeStepper(area, truth, cfg, 4, planner_name="classic-v1",
                             preset_name="exact", seconds=25.0)
    planner = make("classic")
    context, obs = stepper.start()
    planner.reset(context)
    steps = 0
    while obs is not None:
        obs = stepper.step(planner.plan(obs))
        steps += 1
    stepped = stepper.result()
    stepper.close()
    assert steps == direct.iterations
    assert canonical_result(stepped.to_json()) == canonical_result(direct.to_json())


def test_a_stepper_refuses_steps_after_the_end() -> None:
    area = load_area("maze")
    stepper = EpisodeStepper(area, load_ground_truth(area), preset("exact"), 0, seconds=0.5)
    _, obs = stepper.start()
    assert obs is None and stepper.ended  # the start-up turn outlasts the run
    with pytest.raises(RuntimeError, match="ended"):
        stepper.step(None)
    assert stepper.result().sim_seconds == pytest.approx(0.5)
    # Scoring lets go of what only the flight needed, before the final mesh is made.
    assert stepper.loop.sensing.camera.closed
    stepper.close()
