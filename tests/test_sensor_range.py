"""benchmarks/sensor_range.py: the camera's range set in the flown config, a fixed gain-ray
length set to it, a short flight seeing farther with the longer range, bad input refused."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from benchmarks.sensor_range import episode_config, fly, planner_config
from sim.config import preset

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "benchmarks" / "sensor_range.py"


def test_only_the_camera_range_differs_from_the_default_preset() -> None:
    config = episode_config(7.0)
    assert config.camera.max_range_m == 7.0
    default = preset("default")
    assert config.model_copy(update={"camera": default.camera}) == default


def test_fixed_gain_rays_reach_as_far_as_the_camera() -> None:
    assert planner_config("esm-ipp", 7.0, keep_gain_range=False) == {"gain_range_m": 7.0}
    assert planner_config("nbvp", 7.0, keep_gain_range=False) == {"gain_range_m": 7.0}
    assert planner_config("esm-ipp", 7.0, keep_gain_range=True) == {}
    assert planner_config("classic", 7.0, keep_gain_range=False) == {}  # no gain rays


def test_a_longer_range_sees_more_of_an_open_area_in_the_same_time() -> None:
    near = fly("classic", "platform-b", 0, 3.0, 20.0, keep_gain_range=False)
    far = fly("classic", "platform-b", 0, 7.0, 20.0, keep_gain_range=False)
    assert near["camera_range_m"] == 3.0 and far["camera_range_m"] == 7.0
    assert far["coverage"] > near["coverage"] > 0.0


@pytest.mark.parametrize(("args", "message"), [
    (["--planners", "clasic", "--areas", "maze"], "unknown planner"),
    (["--planners", "classic", "--areas", "mazee"], "unknown area"),
    (["--planners", "classic", "--areas", "maze", "--ranges", "0"], "not a positive range"),
])
def test_bad_input_is_named_before_any_flight(args: list[str], message: str) -> None:
    done = subprocess.run([sys.executable, str(SCRIPT), *args], capture_output=True, text=True,
                          cwd=ROOT, timeout=120)
    assert done.returncode != 0
    assert message in done.stderr
