"""What one episode produces, and its JSON form (`result.json`, see `docs/result-format.md`)."""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from sim.metrics import SurfaceScores, timing_summary, volumetric_efficiency

RESULT_FORMAT_VERSION = 1


class RunStatus(enum.StrEnum):
    SUCCEEDED = "succeeded"
    CRASHED = "crashed"
    FAILED = "failed"


@dataclass
class EpisodeResult:
    """Outcome and metrics of one run.

    Series: `volume_times` (S,) seconds and `volume_m3` (S,) explored volume, one per simulated
    second; `recall_times` (R,) and `recall` (R,) surface recall snapshots.
    """

    area: str
    planner: str
    seed: int
    preset: str
    status: RunStatus
    reason: str
    sim_seconds: float
    simulated_until: float
    wall_seconds: float
    explored_volume_m3: float
    observable_volume_m3: float
    coverage: float
    collisions: int
    path_length_m: float
    iterations: int
    planning_times_ms: npt.NDArray[np.float64]
    surface: SurfaceScores
    volume_times: npt.NDArray[np.float64]
    volume_m3: npt.NDArray[np.float64]
    recall_times: npt.NDArray[np.float64]
    recall: npt.NDArray[np.float64]
    frame_costs_ms: dict[str, float] = field(default_factory=dict)
    mesh_vertices: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 3)))
    mesh_triangles: npt.NDArray[np.int32] = field(
        default_factory=lambda: np.zeros((0, 3), dtype=np.int32)
    )
    safety_stops: int = 0
    # Every number the registered measures report (`sim.measures.metric_infos`), None where
    # undefined.
    metrics: dict[str, float | None] = field(default_factory=dict)
    # Per plan call, seconds charged to the simulated clock (N,), and how they were charged.
    charged_s: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    charge: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        return {
            "format_version": RESULT_FORMAT_VERSION,
            "area": self.area,
            "planner": self.planner,
            "seed": self.seed,
            "preset": self.preset,
            "status": self.status.value,
            "reason": self.reason,
            "sim_seconds": self.sim_seconds,
            "simulated_until": self.simulated_until,
            "wall_seconds": self.wall_seconds,
            "explored_volume_m3": self.explored_volume_m3,
            "observable_volume_m3": self.observable_volume_m3,
            "coverage": self.coverage,
            "volumetric_efficiency_m3_per_s": volumetric_efficiency(
                self.explored_volume_m3, self.sim_seconds
            ),
            "collisions": self.collisions,
            "safety_stops": self.safety_stops,
            "path_length_m": self.path_length_m,
            "iterations": self.iterations,
            "planning_time_ms": timing_summary(self.planning_times_ms),
            "planning_charge": {**self.charge,
                                "total_s": float(np.sum(self.charged_s)),
                                "per_call_s": timing_summary(self.charged_s)},
            "surface": _finite(self.surface.as_dict()),
            "frame_costs_ms": self.frame_costs_ms,
            "metrics": dict(self.metrics),
            "series": {
                "time_s": self.volume_times.tolist(),
                "explored_volume_m3": self.volume_m3.tolist(),
                "recall_time_s": self.recall_times.tolist(),
                "surface_recall": self.recall.tolist(),
            },
        }


def _finite(values: dict[str, float]) -> dict[str, float | None]:
    """JSON has no NaN: undefined numbers become null."""
    return {k: (v if np.isfinite(v) else None) for k, v in values.items()}
