"""A finished run's files (`result.json`, recording, mesh) and database rows: its result with
every metric the measures reported, its series, and its stored artifacts."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from server.models import Artifact, Base, MetricSeries, RunResult
from server.storage import StoredArtifact
from worker.result_folder import write_result_folder
from worker.run_record import record_version

if TYPE_CHECKING:
    from sim.result import EpisodeResult

CONTENT_TYPES = {"recording": "application/octet-stream", "mesh": "application/octet-stream",
                 "result": "application/json"}


def write_files(result: EpisodeResult, tmp: Path,
                record: dict[str, Any]) -> dict[str, tuple[Path, str]]:
    return {kind: (path, CONTENT_TYPES[kind])
            for kind, path in write_result_folder(result, tmp, record).items()}


def _f32(values: npt.ArrayLike) -> bytes:
    return np.asarray(values, dtype="<f4").tobytes()


def _opt(value: float) -> float | None:
    return float(value) if np.isfinite(value) else None


def _plain_metrics(metrics: dict[str, Any]) -> dict[str, float | int | None]:
    """The measures' numbers as JSON keeps them: counts whole, others float, undefined None."""
    out: dict[str, float | int | None] = {}
    for key, value in metrics.items():
        if value is None or isinstance(value, bool):
            out[key] = None if value is None else int(value)
        elif isinstance(value, int | np.integer):
            out[key] = int(value)
        else:
            out[key] = _opt(float(value))
    return out


def _result_row(run_id: int, result: EpisodeResult, plateau_s: float,
                record: dict[str, Any]) -> RunResult:
    from sim.metrics import timing_summary, volumetric_efficiency  # the simulation stack

    times = np.asarray(result.volume_times)
    at_plateau = np.asarray(result.volume_m3)[times <= plateau_s + 1e-6]
    timing = timing_summary(result.planning_times_ms)
    surface = result.surface
    return RunResult(
        run_id=run_id, outcome=result.status.value, reason=result.reason,
        simulated_until_s=float(result.simulated_until),
        explored_volume_m3=float(result.explored_volume_m3),
        volume_at_plateau_m3=float(at_plateau[-1]) if len(at_plateau) else 0.0,
        observable_volume_m3=float(result.observable_volume_m3),
        coverage=float(result.coverage),
        volumetric_efficiency=float(volumetric_efficiency(result.explored_volume_m3,
                                                          result.sim_seconds)),
        precision=_opt(surface.precision), recall=_opt(surface.recall),
        fscore=_opt(surface.fscore), rmse_m=_opt(surface.rmse_m),
        collisions=int(result.collisions), path_length_m=float(result.path_length_m),
        iterations=int(result.iterations),
        planning_ms_median=_opt(timing.get("median", float("nan"))),
        planning_ms_mean=_opt(timing.get("mean", float("nan"))),
        planning_ms_max=_opt(timing.get("max", float("nan"))),
        wall_seconds=float(result.wall_seconds),
        benchmark_version=record_version(record), record=record,
        metrics=_plain_metrics(result.metrics))


def result_rows(run_id: int, result: EpisodeResult, plateau_s: float,
                stored: dict[str, tuple[StoredArtifact, str]],
                record: dict[str, Any]) -> list[Base]:
    rows: list[Base] = [
        _result_row(run_id, result, plateau_s, record),
        MetricSeries(run_id=run_id, time_s=_f32(result.volume_times),
                     explored_volume_m3=_f32(result.volume_m3),
                     recall_time_s=_f32(result.recall_times),
                     surface_recall=_f32(result.recall)),
    ]
    for kind, (artifact, ctype) in stored.items():
        rows.append(Artifact(run_id=run_id, kind=kind, location=artifact.location,
                             size_bytes=artifact.size_bytes, sha256=artifact.sha256,
                             content_type=ctype))
    return rows
