"""benchmarks/sensor_range.py: the camera's range set in the flown config, a fixed gain-ray
length set to it, a short flight seeing farther with the longer range, bad input refused."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from benchmarks.sensor_range import (
    episode_config,
    fly,
    parse_settings,
    planner_config,
    settings_for,
)
from sim.config import preset

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "benchmarks" / "sensor_range.py"


def test_only_the_camera_range_differs_from_the_default_preset() -> None:
    config = episode_config(7.0)
    assert config.camera.max_range_m == 7.0
    default = preset("default")
    assert config.model_copy(update={"camera": default.camera}) == default


def test_a_field_of_view_changes_only_the_camera_angles() -> None:
    config = episode_config(7.0, (115.0, 99.3))
    camera = config.camera
    assert (camera.fov_h_deg, camera.fov_v_deg, camera.max_range_m) == (115.0, 99.3, 7.0)
    default = preset("default")
    assert (camera.width, camera.height) == (default.camera.width, default.camera.height)
    assert config.model_copy(update={"camera": default.camera}) == default
    # A wider view puts the same pixels farther apart: a shorter focal length.
    assert camera.intrinsic_matrix()[0, 0] < default.camera.intrinsic_matrix()[0, 0]


def test_settings_apply_to_a_name_or_one_id_and_reach_the_flown_config() -> None:
    settings = parse_settings(["nbvp.extension_m=3", "aep.zero_gain=2",
                               "nbvp-v2.gain_range_m=6.5"])
    assert settings_for("nbvp-v2", settings) == {"extension_m": 3, "gain_range_m": 6.5}
    assert settings_for("nbvp-v1", settings) == {"extension_m": 3}
    assert settings_for("classic-v3", settings) == {}
    run = fly("nbvp", "maze", 0, 7.0, 2.0, keep_gain_range=False,
              settings=settings_for("nbvp-v2", settings))
    # A --set setting wins over the gain range the camera's range would give.
    assert run["planner_config"] == {"gain_range_m": 6.5, "extension_m": 3}
    with pytest.raises(ValueError, match=r"PLANNER\.FIELD=VALUE"):
        parse_settings(["extension_m=3"])
    with pytest.raises(ValueError, match="not a JSON value"):
        parse_settings(["nbvp.extension_m=three"])


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
    (["--planners", "classic", "--areas", "maze", "--fov", "190", "90"], "not a field of view"),
    (["--planners", "nbvp", "--areas", "maze", "--set", "nbvp.extension=3"], "extension"),
    (["--planners", "nbvp", "--areas", "maze", "--set", "nbvp.extension_m=-1"], "greater than"),
])
def test_bad_input_is_named_before_any_flight(args: list[str], message: str) -> None:
    done = subprocess.run([sys.executable, str(SCRIPT), *args], capture_output=True, text=True,
                          cwd=ROOT, timeout=120)
    assert done.returncode != 0
    assert message in done.stderr
