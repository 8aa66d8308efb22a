"""Run recordings: write, save, read back; keyframe replay; rejection of foreign files."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest

from sim.recording import (
    FORMAT,
    VERSION,
    Recording,
    RecordingError,
    RecordingWriter,
    Spool,
    thinned,
)
from sim.voxel_grid import IndexBox

SHAPE = (4, 3, 2)
HEADER = {
    "area": "box",
    "planner": "greedy",
    "seed": 3,
    "grid_shape": list(SHAPE),
    "voxel_size": 0.1,
    "camera": {"width": 160, "height": 120},
}
# Times that float32 represents exactly, so "at or before" is unambiguous.
KEY_TIMES = (1.0, 2.0, 3.0)
PLAN_A = np.array([[1.0, 2.0, 1.5, 0.25], [2.0, 2.5, 1.5, -0.5]])
PLAN_B = np.array([[0.5, 0.5, 1.0, 3.0], [1.5, 0.5, 1.0, 2.0], [1.5, 1.5, 1.25, 1.0]])
SURFACE_POINTS = np.array(
    [
        [0.01, 0.01, 0.01],
        [0.02, 0.03, 0.04],  # same 0.1 m cell as the first: dropped
        [0.5, 0.5, 0.5],
        [0.55, 0.52, 0.58],  # same cell as the previous: dropped
        [1.0, 0.0, 0.0],
        [-0.05, 0.0, 0.0],  # negative coordinate: its own cell
        [0.51, 0.59, 0.53],  # same cell as [0.5, 0.5, 0.5]: dropped
    ]
)
SURFACE_KEPT = SURFACE_POINTS[[0, 2, 4, 5]]


def keyframe_states() -> list[npt.NDArray[np.uint8]]:
    a = np.zeros(SHAPE, dtype=np.uint8)
    a[0, 0, 0] = 1
    a[1, 2, 1] = 2
    a[3, 0, 1] = 1
    b = a.copy()
    b[1, 2, 1] = 1  # changes 2 -> 1 ...
    b[2, 1, 0] = 2
    c = b.copy()
    c[1, 2, 1] = 2  # ... and back 1 -> 2
    c[3, 0, 1] = 0  # back to unknown
    c[0, 1, 1] = 1
    return [a, b, c]


def write(path: Path) -> list[npt.NDArray[np.uint8]]:
    writer = RecordingWriter(header=dict(HEADER))
    for i in range(5):
        writer.pose(0.5 * i, np.array([1.0 + i, 2.0, 1.5]), 0.1 * i)
    writer.plan(0.5, PLAN_A)
    writer.plan(2.5, PLAN_B)
    states = keyframe_states()
    for t, state in zip(KEY_TIMES, states, strict=True):
        writer.map_keyframe(t, state)
    writer.surface(1.0, SURFACE_POINTS, 0.1)
    writer.surface(3.0, np.zeros((0, 3)), 0.1)
    writer.save(path)
    return states


@pytest.fixture
def recording(tmp_path: Path) -> tuple[Recording, list[npt.NDArray[np.uint8]]]:
    path = tmp_path / "run.npz"
    states = write(path)
    return Recording(path), states


def test_header_round_trips(recording: tuple[Recording, list[npt.NDArray[np.uint8]]]) -> None:
    rec, _ = recording
    assert rec.header == {"format": FORMAT, "version": VERSION, **HEADER}
    assert rec.header["format"] == "flybo-recording"
    assert rec.header["version"] == 1


def test_poses(recording: tuple[Recording, list[npt.NDArray[np.uint8]]]) -> None:
    rec, _ = recording
    assert np.array_equal(rec.pose_times, [0.0, 0.5, 1.0, 1.5, 2.0])
    assert rec.poses.shape == (5, 4)
    assert rec.poses.dtype == np.float32
    expected = np.array([[1.0 + i, 2.0, 1.5, 0.1 * i] for i in range(5)], dtype=np.float32)
    assert np.array_equal(rec.poses, expected)


def test_map_state_at_replays_keyframes(
    recording: tuple[Recording, list[npt.NDArray[np.uint8]]],
) -> None:
    rec, (a, b, c) = recording
    zero = np.zeros(SHAPE, dtype=np.uint8)
    cases = [
        (0.0, zero),
        (0.999, zero),
        (1.0, a),
        (1.5, a),
        (1.999, a),
        (2.0, b),
        (2.5, b),
        (3.0, c),
        (100.0, c),
    ]
    for t, expected in cases:
        state = rec.map_state_at(t)
        assert state.shape == SHAPE
        assert state.dtype == np.uint8
        assert np.array_equal(state, expected), f"t = {t}"
    # The voxel that changed twice and the one that went back to unknown.
    assert [rec.map_state_at(t)[1, 2, 1] for t in KEY_TIMES] == [2, 1, 2]
    assert [rec.map_state_at(t)[3, 0, 1] for t in KEY_TIMES] == [1, 1, 0]


def test_keyframes_store_only_changes(
    recording: tuple[Recording, list[npt.NDArray[np.uint8]]],
) -> None:
    rec, (a, b, c) = recording
    offsets = rec.array("keyframe_offsets")
    # a: 3 known voxels; a -> b: 2 changes; b -> c: 3 changes.
    assert offsets.tolist() == [0, 3, 5, 8]
    assert np.array_equal(rec.array("keyframe_times"), KEY_TIMES)
    second = rec.array("keyframe_indices")[3:5]
    assert sorted(second.tolist()) == sorted(
        [int(np.ravel_multi_index(i, SHAPE)) for i in [(1, 2, 1), (2, 1, 0)]]
    )
    assert np.array_equal(b.reshape(-1)[second], rec.array("keyframe_states")[3:5])
    first, third = rec.array("keyframe_indices")[:3], rec.array("keyframe_indices")[5:8]
    assert np.array_equal(first, np.flatnonzero(a))
    assert np.array_equal(a.reshape(-1)[first], rec.array("keyframe_states")[:3])
    assert np.array_equal(c.reshape(-1)[third], rec.array("keyframe_states")[5:8])
    assert rec.array("keyframe_states")[5:8].tolist().count(0) == 1  # back to unknown


def test_plan_at(recording: tuple[Recording, list[npt.NDArray[np.uint8]]]) -> None:
    rec, _ = recording
    assert rec.plan_at(0.0).shape == (0, 4)
    assert np.array_equal(rec.plan_at(0.5), PLAN_A.astype(np.float32))
    assert np.array_equal(rec.plan_at(2.4), PLAN_A.astype(np.float32))
    assert np.array_equal(rec.plan_at(2.5), PLAN_B.astype(np.float32))
    assert np.array_equal(rec.plan_at(50.0), PLAN_B.astype(np.float32))


def test_surface_at(recording: tuple[Recording, list[npt.NDArray[np.uint8]]]) -> None:
    rec, _ = recording
    before = rec.surface_at(0.5)
    assert before.shape == (0, 3)
    first = rec.surface_at(1.0)
    assert first.dtype == np.float32
    # Thinned to one point per 0.1 m cell, keeping the first point of each cell, in order.
    assert np.array_equal(first, SURFACE_KEPT.astype(np.float32))
    assert np.array_equal(rec.surface_at(2.9), first)
    assert rec.surface_at(3.0).shape == (0, 3)
    assert rec.surface_at(10.0).shape == (0, 3)


def test_empty_recording(tmp_path: Path) -> None:
    path = tmp_path / "empty.npz"
    RecordingWriter(header={"grid_shape": [2, 2, 2]}).save(path)
    rec = Recording(path)
    assert rec.poses.shape == (0, 4)
    assert rec.pose_times.shape == (0,)
    assert np.array_equal(rec.map_state_at(10.0), np.zeros((2, 2, 2), dtype=np.uint8))
    assert rec.plan_at(10.0).shape == (0, 4)
    assert rec.surface_at(10.0).shape == (0, 3)


def test_first_keyframe_of_an_empty_map_stores_nothing(tmp_path: Path) -> None:
    writer = RecordingWriter(header={"grid_shape": [3, 3, 3]})
    writer.map_keyframe(1.0, np.zeros((3, 3, 3), dtype=np.uint8))
    full = np.ones((3, 3, 3), dtype=np.uint8)
    writer.map_keyframe(2.0, full)
    writer.map_keyframe(3.0, full)  # no change
    path = tmp_path / "r.npz"
    writer.save(path)
    rec = Recording(path)
    assert rec.array("keyframe_offsets").tolist() == [0, 0, 27, 27]
    assert np.array_equal(rec.map_state_at(2.5), full)
    assert np.array_equal(rec.map_state_at(3.5), full)


def save_npz(path: Path, header: object) -> None:
    np.savez_compressed(path, header=np.array(json.dumps(header)))


@pytest.mark.parametrize(
    "header",
    [
        {"format": "something-else", "version": VERSION, "grid_shape": [1, 1, 1]},
        {"format": FORMAT, "version": VERSION + 1, "grid_shape": [1, 1, 1]},
        {"format": FORMAT, "grid_shape": [1, 1, 1]},
        {"version": VERSION},
    ],
)
def test_wrong_format_or_version_raises(tmp_path: Path, header: dict[str, object]) -> None:
    path = tmp_path / "foreign.npz"
    save_npz(path, header)
    with pytest.raises(RecordingError):
        Recording(path)


def test_missing_or_corrupt_header_raises(tmp_path: Path) -> None:
    no_header = tmp_path / "no_header.npz"
    np.savez_compressed(no_header, poses=np.zeros((1, 4)))
    with pytest.raises(RecordingError):
        Recording(no_header)
    bad_json = tmp_path / "bad_json.npz"
    np.savez_compressed(bad_json, header=np.array("{not json"))
    with pytest.raises(RecordingError):
        Recording(bad_json)


def test_garbage_and_missing_files_raise(tmp_path: Path) -> None:
    garbage = tmp_path / "garbage.npz"
    garbage.write_bytes(b"this is not a recording at all " * 20)
    with pytest.raises(RecordingError):
        Recording(garbage)
    with pytest.raises(RecordingError):
        Recording(tmp_path / "does_not_exist.npz")
    assert issubclass(RecordingError, ValueError)


def _thinned_whole(points: np.ndarray, voxel_m: float) -> np.ndarray:
    """The thinning as one computation over the whole cloud (the reference)."""
    pts = np.asarray(points, dtype=np.float64)
    cells = np.floor(pts / voxel_m).astype(np.int64)
    cells -= cells.min(axis=0)
    span = cells.max(axis=0) + 1
    keys = (cells[:, 0] * span[1] + cells[:, 1]) * span[2] + cells[:, 2]
    _, first = np.unique(keys, return_index=True)
    return pts[np.sort(first)].astype(np.float32)


@pytest.mark.parametrize(("chunk", "bitmap"), [(1, False), (7, False), (1000, False),
                                               (1 << 20, False), (1 << 20, True)])
def test_snapshots_thinned_in_chunks_are_thinned_as_a_whole(
    chunk: int, bitmap: bool, monkeypatch: pytest.MonkeyPatch,
) -> None:
    """By the bitmap of cells met, or (bounds too large for one) by sorted keys computed a
    chunk at a time: the thinning of the whole cloud at once either way."""
    import sim.recording

    if not bitmap:
        monkeypatch.setattr(sim.recording, "MAX_BITMAP_CELLS", 0)
    rng = np.random.default_rng(5)
    # float32 points, as the TSDF gives them, many on cell faces and many sharing a cell.
    points = np.concatenate([
        rng.uniform(-3.0, 7.0, size=(3000, 3)),
        np.round(rng.uniform(-3.0, 7.0, size=(2000, 3)), 1),
        np.repeat(rng.uniform(0.0, 1.0, size=(50, 3)), 20, axis=0),
    ]).astype(np.float32)
    rng.shuffle(points)
    got = thinned(points, 0.1, chunk)
    assert got.dtype == np.float32
    np.testing.assert_array_equal(got, _thinned_whole(points, 0.1))
    assert len(got) < len(points)
    assert len(thinned(points[:0], 0.1, chunk)) == 0


def test_the_archive_holds_the_sequences_as_if_concatenated(tmp_path: Path) -> None:
    """`save` writes each flat sequence item by item; the arrays read back are those of one
    concatenation, with the dtypes and shapes of the format (`docs/recording.md`)."""
    rng = np.random.default_rng(4)
    writer = RecordingWriter(header=dict(HEADER))
    surfaces = [rng.uniform(0.0, 9.0, (n, 3)) for n in (0, 40, 7)]
    plans = [rng.uniform(0.0, 9.0, (n, 4)) for n in (3, 1)]
    for i, points in enumerate(surfaces):
        writer.surface(float(i), points, 0.05)
    for i, plan in enumerate(plans):
        writer.plan(float(i), plan)
    states = keyframe_states()
    for i, state in enumerate(states):
        writer.map_keyframe(float(i), state)
    path = tmp_path / "r.npz"
    writer.save(path)
    with np.load(path, allow_pickle=False) as data:
        arrays = {k: data[k] for k in data.files}
    expected_surface = np.concatenate([thinned(p, 0.05) for p in surfaces]).astype(np.float32)
    np.testing.assert_array_equal(arrays["surface_points"], expected_surface)
    assert arrays["surface_points"].dtype == np.float32
    np.testing.assert_array_equal(arrays["plan_waypoints"],
                                  np.concatenate(plans).astype(np.float32))
    assert arrays["plan_offsets"].tolist() == [0, 3, 4]
    assert arrays["keyframe_indices"].dtype == np.uint32
    assert arrays["keyframe_states"].dtype == np.uint8
    assert len(arrays["keyframe_indices"]) == arrays["keyframe_offsets"][-1]
    assert sorted(arrays) == sorted([
        "header", "pose_times", "poses", "keyframe_times", "keyframe_offsets",
        "keyframe_indices", "keyframe_states", "plan_times", "plan_offsets", "plan_waypoints",
        "surface_times", "surface_offsets", "surface_points"])
    replayed = Recording(path)
    np.testing.assert_array_equal(replayed.map_state_at(10.0), states[-1])


def test_keyframes_compared_in_the_changed_box_are_those_of_the_whole_grid(
        tmp_path: Path) -> None:
    # The same map history written twice: once comparing whole grids, once told a box that
    # holds every change since the previous keyframe (sometimes larger, sometimes empty).
    rng = np.random.default_rng(8)
    shape = (9, 7, 5)
    whole, boxed = RecordingWriter(header=dict(HEADER)), RecordingWriter(header=dict(HEADER))
    state = np.zeros(shape, dtype=np.uint8)
    state[2:5, 1:4, 0:3] = 1
    whole.map_keyframe(0.0, state)
    boxed.map_keyframe(0.0, state)
    for t in range(1, 40):
        state = state.copy()
        box = IndexBox((0, 0, 0), (0, 0, 0))  # nothing changed
        if t % 7:
            lo = rng.integers(0, shape)
            hi = np.minimum(lo + rng.integers(1, 5, size=3), shape)
            region = state[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]]
            region[...] = rng.choice(np.array([0, 1, 2], dtype=np.uint8), size=region.shape)
            grown = np.maximum(lo - rng.integers(0, 2, size=3), 0)
            box = IndexBox(tuple(int(v) for v in grown), tuple(int(v) for v in hi))
        whole.map_keyframe(float(t), state)
        boxed.map_keyframe(float(t), state, box)
    whole.save(tmp_path / "whole.npz")
    boxed.save(tmp_path / "boxed.npz")
    a, b = Recording(tmp_path / "whole.npz"), Recording(tmp_path / "boxed.npz")
    for name in ("keyframe_times", "keyframe_offsets", "keyframe_indices", "keyframe_states"):
        assert a.array(name).dtype == b.array(name).dtype
        assert np.array_equal(a.array(name), b.array(name)), name
    assert len(a.array("keyframe_times")) == 40
    assert len(a.array("keyframe_indices")) > 100


def test_saved_twice_the_same_archive_and_closed_after(tmp_path: Path) -> None:
    # The sequences wait in temporary files: saving reads them from the start each time, and
    # the writer goes on appending after a save.
    writer = RecordingWriter(header=dict(HEADER))
    writer.map_keyframe(0.0, keyframe_states()[0])
    writer.surface(1.0, SURFACE_POINTS, 0.1)
    writer.save(tmp_path / "a.npz")
    writer.save(tmp_path / "b.npz")
    a, b = Recording(tmp_path / "a.npz"), Recording(tmp_path / "b.npz")
    for name in ("keyframe_indices", "keyframe_states", "surface_points", "surface_offsets"):
        assert np.array_equal(a.array(name), b.array(name)), name
    writer.surface(2.0, SURFACE_POINTS[:3], 0.1)
    writer.save(tmp_path / "c.npz")
    c = Recording(tmp_path / "c.npz")
    assert np.array_equal(c.surface_at(1.5), a.surface_at(1.5))
    assert len(c.surface_at(2.5)) == len(thinned(SURFACE_POINTS[:3], 0.1))
    writer.close()
    with pytest.raises(ValueError):
        writer.save(tmp_path / "d.npz")


def test_a_spool_refuses_rows_of_another_width() -> None:
    spool = Spool(np.float32, 3)
    spool.append(np.zeros((4, 3)))
    with pytest.raises(ValueError, match="rows"):
        spool.append(np.zeros((4, 2), dtype=np.float32))
    assert spool.lengths == [4]
    spool.close()
