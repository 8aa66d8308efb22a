"""What the episode keeps from the voxels a frame changed (masks, frontier rows, keyframes, the
safety monitor's map) equals what recounting the whole grid gives."""

from __future__ import annotations

import numpy as np
import pytest

from sim.config import preset
from sim.episode_recorder import _NOTHING
from sim.flight import startup_spin
from sim.map_view import MappingStack
from sim.occupancy import OccupancyMap, VoxelState
from sim.recording import RecordingWriter
from sim.safety_monitor import SafetyMonitor
from sim.stage_costs import StageCosts
from tests.sim.test_frontiers import integrate_random, reference_frontier


def stack(shape: tuple[int, int, int] = (24, 20, 12)) -> MappingStack:
    return MappingStack(np.zeros(3), shape, 0.1, 0.45)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_state_masks_follow_the_map(seed: int) -> None:
    rng = np.random.default_rng(seed)
    s = stack()
    for step in range(12):
        integrate_random(s.occupancy, rng, 200, hit_share=0.4)
        if step % 3:  # asked for now and then, as planners do
            continue
        view = s.view()
        state = s.occupancy.state
        assert np.array_equal(view.free, state == VoxelState.FREE)
        assert np.array_equal(view.occupied, state == VoxelState.OCCUPIED)
        assert not view.free.flags.writeable


@pytest.mark.parametrize("seed", [0, 1])
def test_frontier_rows_and_listing_match_a_recount(seed: int) -> None:
    rng = np.random.default_rng(seed)
    s = stack()
    for _ in range(10):
        integrate_random(s.occupancy, rng, 300)
        s.frontiers.update()
        frontier = reference_frontier(s.occupancy.state)
        assert np.array_equal(s.frontiers.frontier, frontier)
        assert np.array_equal(s.frontiers._rows, frontier.sum(axis=2))
        listed = np.concatenate([c.indices for c in s.frontiers.clusters(min_size=1)])
        assert sorted(map(tuple, listed)) == sorted(map(tuple, np.argwhere(frontier)))


def test_keyframes_from_dirty_boxes_equal_full_comparisons() -> None:
    rng = np.random.default_rng(3)
    m = OccupancyMap(np.zeros(3), (16, 14, 10), 0.1)
    changes = m.subscribe()
    boxed, full = RecordingWriter(header={}), RecordingWriter(header={})
    boxed.map_keyframe(0.0, m.state)
    full.map_keyframe(0.0, m.state)
    for t in range(1, 8):
        for _ in range(t % 3):  # some keyframes with no change at all
            integrate_random(m, rng, 150, hit_share=0.5)
        box = changes.take()
        boxed.map_keyframe(float(t), m.state, box or _NOTHING)
        full.map_keyframe(float(t), m.state)
    assert len(boxed._key_indices) == 8
    for a, b in zip(boxed._key_indices, full._key_indices, strict=True):
        assert np.array_equal(a, b)
    for a, b in zip(boxed._key_states, full._key_states, strict=True):
        assert np.array_equal(a, b)
    assert sum(len(a) for a in full._key_indices[1:]) > 0


def test_the_safety_monitor_keeps_the_map_as_it_was_at_each_guard() -> None:
    rng = np.random.default_rng(4)
    s = stack()
    config = preset("exact")
    monitor = SafetyMonitor(config, s, StageCosts())
    for update in range(5):
        integrate_random(s.occupancy, rng, 250, hit_share=0.5)
        flight = startup_spin(np.array([1.0, 1.0, 0.6, 0.0]), 0.0, config.limits)
        monitor.guard(flight, update)
        expected = s.occupancy.copy_state()
        integrate_random(s.occupancy, rng, 250, hit_share=0.5)  # after the guard
        assert flight.checked_on is not None
        assert np.array_equal(flight.checked_on, expected)
