"""What the viewer reads: the map timeline against the recording, frontiers, the final mesh
simplification and colours, and loading runs from files and from the service's database."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from sim.recording import Recording, RecordingWriter
from tests.replay.conftest import SECONDS, ServiceDb
from web.replay.extras import (
    DISTANCE_SATURATION_M,
    cluster_mesh,
    compute_extras,
    distance_colours,
)
from web.replay.source import RunLookupError, load_file_run, load_stored_run, recent_runs
from web.replay.timeline import FREE, OCCUPIED, MapTimeline, frontier_mask


def test_timeline_matches_the_recording_at_every_keyframe(tmp_path: Path) -> None:
    shape = (6, 5, 4)
    rng = np.random.default_rng(0)
    writer = RecordingWriter(header={"grid_shape": list(shape), "voxel_size": 0.5,
                                     "grid_origin": [1.0, 2.0, 3.0]})
    state = np.zeros(shape, dtype=np.uint8)
    for k in range(11):
        # Random changes, including voxels going back to unknown.
        flip = rng.random(shape) < 0.2
        state = np.where(flip, rng.integers(0, 3, shape), state).astype(np.uint8)
        writer.map_keyframe(2.0 * k, state)
    path = tmp_path / "r.npz"
    writer.save(path)
    rec = Recording(path)
    timeline = MapTimeline(rec, checkpoint_every=4)  # lookups through checkpoints and deltas
    for k, t in enumerate(timeline.times):
        expected = rec.map_state_at(float(t))
        assert np.array_equal(timeline.state(k), expected), k
        assert timeline.known_counts[k] == np.count_nonzero(expected)
        assert timeline.known_volume_m3(float(t) + 0.5) == np.count_nonzero(expected) * 0.125
    assert timeline.keyframe_at(-1.0) == -1
    assert not timeline.state(-1).any()
    layers = timeline.layers(10)
    occupied = np.argwhere(timeline.state(10) == OCCUPIED)
    assert np.allclose(layers.occupied, np.array([1.0, 2.0, 3.0]) + (occupied + 0.5) * 0.5)


def test_frontiers_are_free_voxels_next_to_unknown_ones() -> None:
    state = np.zeros((5, 3, 3), dtype=np.uint8)
    state[:3] = FREE  # free slab i = 0..2, unknown beyond
    state[1, 1, 1] = OCCUPIED
    mask = frontier_mask(state)
    # Only the free voxels facing the unknown slab at i = 3; the grid border is no frontier.
    assert np.array_equal(np.argwhere(mask)[:, 0], np.full(9, 2))
    state[3:] = FREE
    assert not frontier_mask(state).any()


def test_cluster_mesh_merges_close_vertices_and_drops_collapsed_faces() -> None:
    # A 1 m square of 2 x 20 x 20 triangles.
    n = 21
    u, v = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n), indexing="ij")
    vertices = np.stack([u.ravel(), v.ravel(), np.zeros(n * n)], axis=1)
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    faces = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                            np.stack([a, c, d], -1).reshape(-1, 3)])
    shown, shown_faces = cluster_mesh(vertices, faces, 0.26)
    assert len(shown) < len(vertices) / 10
    assert 0 < len(shown_faces) < len(faces) / 10
    assert shown_faces.max() < len(shown)
    assert np.all(shown_faces[:, 0] != shown_faces[:, 1])
    assert np.allclose(shown[:, 2], 0.0)  # still the same plane
    assert shown[:, :2].min() >= 0.0 and shown[:, :2].max() <= 1.0


def test_distance_colours_run_from_green_to_red() -> None:
    colours = distance_colours(np.array([0.0, DISTANCE_SATURATION_M / 2, 1.0, 5.0]))
    green, yellow, red, red_too = colours.astype(int)
    assert green[1] > green[0] and green[1] > green[2]
    assert yellow[0] > 200 and yellow[1] > 200
    assert red[0] > 200 and red[1] < 60
    assert np.array_equal(red, red_too)


def test_file_run_reads_the_folder_of_flybo_run(run_dir: Path) -> None:
    run = load_file_run(run_dir / "recording.npz")
    result = json.loads((run_dir / "result.json").read_text())
    assert run.area.name == "maze"
    assert run.duration == pytest.approx(SECONDS, abs=0.2)
    assert run.mesh_path == (run_dir / "mesh.ply").resolve()
    assert run.volume_at(SECONDS) == pytest.approx(result["explored_volume_m3"])
    assert run.recall is not None and run.recall_at(SECONDS) is not None
    # The curve from the keyframes agrees with the run's own curve.
    assert run.timeline.known_volume_m3(SECONDS) == pytest.approx(
        result["explored_volume_m3"], rel=0.05)
    assert "classic" in run.title and "maze" in run.title


def test_file_run_without_result_falls_back_to_the_keyframes(run_dir: Path,
                                                             tmp_path: Path) -> None:
    shutil.copy(run_dir / "recording.npz", tmp_path / "recording.npz")
    run = load_file_run(tmp_path / "recording.npz")
    assert run.mesh_path is None and run.recall is None
    assert run.volume_at(SECONDS) == pytest.approx(run.timeline.known_volume_m3(SECONDS))
    assert run.volume_at(SECONDS) > run.volume_at(2.0) > 0


def test_extras_colour_the_final_mesh(run_dir: Path) -> None:
    extras = compute_extras(load_file_run(run_dir / "recording.npz"))
    assert 0 < len(extras.truth_points) <= 150_000
    mesh = extras.final_mesh
    assert mesh is not None and len(mesh.faces) > 100
    assert mesh.source_faces >= len(mesh.faces)
    # A faithful 20 s reconstruction: most shown vertices lie within 5 cm of the truth.
    assert np.median(mesh.distances) < 0.05
    glb = mesh.glb(2.35)
    assert glb[:4] == b"glTF" and mesh.glb(2.35) is glb


def test_bad_files_are_refused(tmp_path: Path) -> None:
    with pytest.raises(RunLookupError, match="no recording"):
        load_file_run(tmp_path / "missing.npz")
    garbage = tmp_path / "garbage.npz"
    garbage.write_bytes(b"not a recording" * 10)
    with pytest.raises(RunLookupError):
        load_file_run(garbage)


def test_stored_runs_load_from_database_and_store(service_db: ServiceDb) -> None:
    from server.storage import open_store

    store = open_store(service_db.settings.artifacts)
    first, second = service_db.with_recording
    run = load_stored_run(service_db.sessions, store, first)
    assert run.key == f"run:{first}"
    assert run.title.startswith(f"run {first}: classic-v1 on maze")
    assert run.mesh_path is not None
    assert run.volume_at(7.5) == pytest.approx(70.0)  # the stored series, not the keyframes
    assert run.recall_at(15.0) == pytest.approx(0.1)
    assert load_stored_run(service_db.sessions, store, second).mesh_path is None
    with pytest.raises(RunLookupError, match="no recording"):
        load_stored_run(service_db.sessions, store, service_db.without_recording)
    with pytest.raises(RunLookupError, match="does not exist"):
        load_stored_run(service_db.sessions, store, 999)
    listed = recent_runs(service_db.sessions)
    assert [i for i, _ in listed] == [second, first]  # newest first, only with a recording
    assert "maze" in listed[0][1]
