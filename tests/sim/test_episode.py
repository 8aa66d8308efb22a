"""End-to-end episodes: Classic on MAZE for a short time."""

from __future__ import annotations

import numpy as np
import pytest

from areas import load_area, load_ground_truth
from planners.registry import make
from sim.config import preset
from sim.episode import run_episode
from sim.recording import Recording
from sim.result import EpisodeResult, RunStatus


def _run(seed: int, preset_name: str, seconds: float, *, charge_planning_time: bool = True,
         **kwargs: object) -> EpisodeResult:
    area = load_area("maze")
    config = preset(preset_name)
    if not charge_planning_time:
        config = config.model_copy(update={"planning_time_charge": "none"})
    return run_episode(area, load_ground_truth(area), make("classic"), config, seed,
                       planner_name="classic-v1", preset_name=preset_name, seconds=seconds,
                       **kwargs)  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def short_run() -> EpisodeResult:
    # Sensor and odometry noise on, but the planner's wall time is not charged to the clock:
    # the flight is then the same on every machine, so the thresholds below hold everywhere.
    return _run(0, "default", 60.0, charge_planning_time=False)


def test_explored_volume_grows_without_collision(short_run: EpisodeResult) -> None:
    assert short_run.status is RunStatus.SUCCEEDED
    assert short_run.collisions == 0
    volume = short_run.volume_m3
    assert len(volume) == 61  # one sample per simulated second, t = 0 .. 60
    assert np.all(np.diff(volume) >= 0)  # known voxels never become unknown again
    assert volume[-1] > 1.5 * volume[0] > 0
    assert short_run.path_length_m > 5.0
    assert short_run.iterations >= 3
    assert 0 < short_run.coverage < 1


def test_surface_metrics_are_sane(short_run: EpisodeResult) -> None:
    surface = short_run.surface
    # What is reconstructed lies on the truth. After one noisy minute, seeds 0-3 give precision
    # 0.69-0.94 and RMSE 0.025-0.047 m; a wrong camera frame or pose would give far less.
    assert surface.precision > 0.7
    assert 0 < surface.recall < 0.5  # a minute covers a small part of the maze
    assert surface.rmse_m < 0.06
    assert len(short_run.recall) == 3  # snapshots at 20, 40, 60 s
    assert np.all(np.diff(short_run.recall) >= -0.01)


def test_same_seed_without_time_charge_is_repeatable(tmp_path: object) -> None:
    first = _run(3, "exact", 30.0)
    second = _run(3, "exact", 30.0)
    np.testing.assert_array_equal(first.volume_m3, second.volume_m3)
    assert first.path_length_m == second.path_length_m
    assert first.iterations == second.iterations
    assert first.surface == second.surface


def test_recording_holds_the_flight(tmp_path: object) -> None:
    from pathlib import Path

    path = Path(str(tmp_path)) / "recording.npz"
    result = _run(1, "exact", 25.0, recording_path=path)
    rec = Recording(path)
    assert rec.header["area"] == "maze"
    assert rec.header["grid_shape"] == [200, 200, 25]
    assert len(rec.poses) >= 25 * 10  # 10 Hz
    final = rec.map_state_at(25.0)
    assert np.count_nonzero(final) * 0.1**3 == pytest.approx(result.explored_volume_m3, rel=0.05)
    assert len(rec.plan_at(25.0)) >= 1


def test_planner_exception_fails_the_run() -> None:
    class Broken:
        def reset(self, ctx: object) -> None:
            pass

        def plan(self, obs: object) -> object:
            raise RuntimeError("boom")

    area = load_area("maze")
    result = run_episode(area, load_ground_truth(area), Broken(), preset("exact"), 0,
                         seconds=20.0)  # type: ignore[arg-type]
    assert result.status is RunStatus.FAILED
    assert "boom" in result.reason
