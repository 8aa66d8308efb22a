"""Loading a run to replay: from a recording file, or from the database and the artifact store.

A run folder written by `flybo run` holds `recording.npz`, `mesh.ply` and `result.json` (with the
metric curves); a service run has the `recording` and `mesh` artifacts and a `metric_series` row.
Either way the viewer gets one `RunData`.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from areas import Area, load_area
from server.models import PUBLIC_SPLIT, AreaRow, Artifact, MetricSeries, Run
from server.storage import ArtifactStore, ArtifactStoreError
from sim.camera import CameraConfig
from sim.recording import Recording, RecordingError
from web.replay.timeline import MapTimeline

FloatArray = npt.NDArray[np.float64]


class RunLookupError(LookupError):
    """The run to replay does not exist or cannot be replayed; the message is for the user."""


@dataclass(frozen=True)
class Series:
    """A metric curve.

    Attributes:
        times: (T,) simulated seconds, increasing.
        values: (T,) the metric at each time.
    """

    times: FloatArray
    values: FloatArray

    def at(self, time: float) -> float | None:
        """The last value at or before `time`; None before the first sample."""
        i = int(np.searchsorted(self.times, time, side="right")) - 1
        return None if i < 0 else float(self.values[i])

    @staticmethod
    def of(times: Any, values: Any) -> Series | None:
        t = np.asarray(times, dtype=np.float64).reshape(-1)
        v = np.asarray(values, dtype=np.float64).reshape(-1)
        return Series(t, v) if len(t) and len(t) == len(v) else None


@dataclass
class RunData:
    """Everything the viewer shows of one run, except what `web.replay.extras` computes later.

    Attributes:
        key: cache key, ``run:<id>`` or ``file:<absolute path>``.
        title: one line for the user.
        recording: the run recording.
        timeline: the map at every keyframe.
        area: the area flown (its mesh is drawn).
        camera: the recorded camera model (the frustum).
        duration: last recorded time, s.
        volume: explored volume curve, m³ (the run's series; else from the keyframes).
        recall: surface recall curve, or None when the run has none.
        mesh_path: the final mesh file, or None.
    """

    key: str
    title: str
    recording: Recording
    timeline: MapTimeline
    area: Area
    camera: CameraConfig
    duration: float
    volume: Series
    recall: Series | None
    mesh_path: Path | None

    def volume_at(self, time: float) -> float:
        value = self.volume.at(time)
        return 0.0 if value is None else value

    def recall_at(self, time: float) -> float | None:
        return None if self.recall is None else self.recall.at(time)


def _build(key: str, title: str, recording_path: Path, mesh_path: Path | None,
           volume: Series | None, recall: Series | None) -> RunData:
    try:
        recording = Recording(recording_path)
    except RecordingError as exc:
        raise RunLookupError(str(exc)) from None
    header = recording.header
    try:
        area = load_area(str(header["area"]))
    except (KeyError, ValueError) as exc:
        raise RunLookupError(f"the area of this recording is not available: {exc}") from None
    timeline = MapTimeline(recording)
    ends = [float(a[-1]) for a in (recording.pose_times, timeline.times) if len(a)]
    duration = max(ends, default=0.0)
    if volume is None:
        # Runs without a stored curve: the known voxels of each keyframe give the same metric
        # (the grid covers exactly the area's explorable box).
        volume = Series(timeline.times, np.asarray(
            timeline.known_counts * timeline.voxel_size ** 3, dtype=np.float64))
    camera = CameraConfig(**header.get("camera", {}))
    return RunData(key=key, title=title, recording=recording, timeline=timeline, area=area,
                   camera=camera, duration=duration, volume=volume, recall=recall,
                   mesh_path=mesh_path)


def _title(header: dict[str, Any], prefix: str) -> str:
    return (f"{prefix}{header.get('planner', '?')} on {header.get('area', '?')}, "
            f"seed {header.get('seed', '?')}, preset {header.get('preset', '?')}")


def load_file_run(path: Path) -> RunData:
    """A run from its recording file; `mesh.ply` and `result.json` beside it are used if present.
    """
    path = path.expanduser().resolve()
    if not path.is_file():
        raise RunLookupError(f"no recording at {path}")
    mesh = path.parent / "mesh.ply"
    volume = recall = None
    result = path.parent / "result.json"
    if result.is_file():
        try:
            series = json.loads(result.read_text())["series"]
            volume = Series.of(series["time_s"], series["explored_volume_m3"])
            recall = Series.of(series["recall_time_s"], series["surface_recall"])
        except (OSError, ValueError, KeyError, TypeError):
            volume = recall = None  # a foreign or damaged result: fall back to the recording
    data = _build(f"file:{path}", "", path, mesh if mesh.is_file() else None, volume, recall)
    data.title = _title(data.recording.header, f"{path.parent.name}: ")
    return data


def _floats(blob: bytes | None) -> FloatArray:
    """A series column: little-endian float32 (see `server.models.MetricSeries`)."""
    return np.frombuffer(blob or b"", dtype="<f4").astype(np.float64)


@dataclass(frozen=True)
class StoredRun:
    """Where a service run's artifacts are, read from the database in one short session."""

    run_id: int
    title: str
    recording: str
    mesh: str | None
    volume: Series | None
    recall: Series | None


def find_stored_run(session: Session, run_id: int) -> StoredRun:
    """The run's artifact locations and curves.

    Raises:
        RunLookupError: no such run, or it has no recording (not finished, or failed early).
    """
    run = session.get(Run, run_id)
    if run is None:
        raise RunLookupError(f"run {run_id} does not exist")
    if run.area.split != PUBLIC_SPLIT:  # the viewer is public: held-out scenes stay unseen
        raise RunLookupError(f"run {run_id} flew a held-out area, whose scene is not shown")
    artifacts = {a.kind: a.location for a in session.scalars(
        select(Artifact).where(Artifact.run_id == run_id))}
    if "recording" not in artifacts:
        raise RunLookupError(f"run {run_id} has no recording yet (status {run.status})")
    series = session.get(MetricSeries, run_id)
    volume = recall = None
    if series is not None:
        volume = Series.of(_floats(series.time_s), _floats(series.explored_volume_m3))
        recall = Series.of(_floats(series.recall_time_s), _floats(series.surface_recall))
    planner = run.job.planner.key if run.job is not None else "?"
    title = f"run {run_id}: {planner} on {run.area.name}, seed {run.seed}, preset {run.preset}"
    return StoredRun(run_id, title, artifacts["recording"], artifacts.get("mesh"), volume, recall)


def load_stored_run(sessions: sessionmaker[Session], store: ArtifactStore,
                    run_id: int) -> RunData:
    """A service run: its row and series from the database, its files from the artifact store."""
    with sessions() as session:
        stored = find_stored_run(session, run_id)
    try:
        recording = store.open_path(stored.recording)
        mesh = store.open_path(stored.mesh) if stored.mesh else None
    except ArtifactStoreError as exc:
        raise RunLookupError(str(exc)) from None
    return _build(f"run:{run_id}", stored.title, recording, mesh, stored.volume, stored.recall)


def recent_runs(sessions: sessionmaker[Session], limit: int = 50) -> list[tuple[int, str]]:
    """(run id, label) of the latest runs that have a recording, newest first."""
    with sessions() as session:
        rows = session.execute(
            select(Run.id, Run.status, Run.seed, AreaRow.name)
            .join(AreaRow, AreaRow.id == Run.area_id)
            .join(Artifact, (Artifact.run_id == Run.id) & (Artifact.kind == "recording"))
            .where(AreaRow.split == PUBLIC_SPLIT)
            .order_by(Run.id.desc()).limit(limit)).all()
        return [(int(r[0]), f"run {r[0]}: {r[3]}, seed {r[2]} ({r[1]})") for r in rows]
