"""The metric details that move numbers: grid ties, the truth sample, the final keyframe, what
coverage counts, and which exceptions are the platform's."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace
from typing import cast

import numpy as np
import pytest

from areas import load_area, load_ground_truth
from areas.surface_cloud import SurfaceCloud
from planners.registry import make
from sim.config import preset
from sim.episode import run_episode
from sim.interface import Observation, Plan, PlannerContext
from sim.measures import EpisodeView
from sim.measures.final import SurfaceQuality
from sim.measures.series import RecallSeries
from sim.metrics import TIE_TOLERANCE_M, surface_scores
from sim.recording import Recording
from sim.result import RunStatus


def test_a_vertex_at_tau_counts_whatever_its_rounding() -> None:
    # Truth on z = 0; the reconstruction at z = tau as float32 stores it (0.0500000007 m): a
    # tie the float's rounding decided, which without a tolerance counted as a miss.
    truth = np.array([[x, y, 0.0] for x in np.linspace(0, 1, 11) for y in np.linspace(0, 1, 11)])
    recon = (truth + np.array([0.0, 0.0, 0.05])).astype(np.float32).astype(np.float64)
    assert np.all(recon[:, 2] > 0.05)
    scores = surface_scores(recon, truth, 0.05)
    assert scores.precision == 1.0 and scores.recall == 1.0
    # Beyond the tolerance it no longer counts.
    far = truth + np.array([0.0, 0.0, 0.05 + 2 * TIE_TOLERANCE_M])
    assert surface_scores(far, truth, 0.05).precision == 0.0


def _view(seed: int) -> EpisodeView:
    points = np.random.default_rng(7).random((50_000, 3)).astype(np.float32)
    cfg = preset("default").model_copy(update={"final_recall_points": 1000,
                                               "recall_sample_points": 1000})
    truth = SimpleNamespace(surface=SurfaceCloud.of(points))
    return cast(EpisodeView, SimpleNamespace(truth=truth, config=cfg, seed=seed))


def test_the_truth_sample_does_not_depend_on_the_run_seed() -> None:
    final = [SurfaceQuality(), SurfaceQuality()]
    snapshots = [RecallSeries(), RecallSeries()]
    for seed, f, s in zip((0, 1), final, snapshots, strict=True):
        f.reset(_view(seed))
        s.reset(_view(seed))
    assert len(final[0].truth) == 1000
    np.testing.assert_array_equal(final[0].truth, final[1].truth)
    np.testing.assert_array_equal(snapshots[0].points, snapshots[1].points)


def test_the_recording_ends_on_the_scored_map(tmp_path: Path) -> None:
    area = load_area("maze")
    path = tmp_path / "recording.npz"
    # 11.3 s: the keyframes (every 2 s) stop at 10 s.
    result = run_episode(area, load_ground_truth(area), make("classic"), preset("exact"), 0,
                         seconds=11.3, recording_path=path)
    rec = Recording(path)
    final = rec.map_state_at(result.simulated_until)
    assert np.count_nonzero(final) * area.voxel_size**3 == pytest.approx(
        result.explored_volume_m3, abs=1e-9)
    observable = result.metrics["explored_observable_m3"]
    assert observable is not None and 0 < observable <= result.explored_volume_m3
    assert result.coverage == pytest.approx(observable / result.observable_volume_m3)


class _TimedOutError(Exception):
    """Stands for a worker's soft time limit (an Exception subclass, as Celery's is)."""


class _SlowPlanner:
    def reset(self, ctx: PlannerContext) -> None:
        pass

    def plan(self, obs: Observation) -> Plan:
        raise _TimedOutError("soft time limit")


def test_a_platform_timeout_ends_the_run_instead_of_being_the_planners_failure() -> None:
    area = load_area("maze")
    truth = load_ground_truth(area)
    cfg = preset("exact").model_copy(update={"startup_spin": False})
    failed = run_episode(area, truth, _SlowPlanner(), cfg, 0, seconds=5)
    assert failed.status is RunStatus.FAILED and "planner raised _TimedOutError" in failed.reason
    with pytest.raises(_TimedOutError):
        run_episode(area, truth, _SlowPlanner(), cfg, 0, seconds=5,
                    platform_errors=(_TimedOutError,))
