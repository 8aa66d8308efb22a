"""Measures of the run's end state: coverage, the reconstructed surface and its quality."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from sim.measures.base import EpisodeEnd, EpisodeView, Measure, MetricInfo
from sim.metrics import SurfaceScores, coverage, surface_scores


@dataclass(frozen=True)
class CoverageResult:
    """`explored_observable_m3`: known voxels that could be observed, m³; `coverage`: that over
    the observable volume."""

    explored_observable_m3: float
    coverage: float


class Coverage(Measure):
    """Absolute coverage: explored voxels that could be observed, over the observable volume.
    Noise also marks voxels inside walls, which are not counted, here or in the explored
    observable volume that the paper's relative coverage is computed from."""

    name = "coverage"
    metrics = (
        MetricInfo("coverage", "coverage", leaderboard=True),
        MetricInfo("explored_observable_m3", "explored observable volume", unit="m³", fmt=".1f"),
    )

    def result(self, ep: EpisodeView, end: EpisodeEnd,
               done: Mapping[str, Any]) -> CoverageResult:
        known = ep.mapping.occupancy.state != 0
        explored = float(np.count_nonzero(known & ep.truth.observable)) * ep.area.voxel_size**3
        return CoverageResult(explored, coverage(explored, ep.truth.observable_volume_m3))

    def scalars(self, value: Any) -> dict[str, float | None]:
        result: CoverageResult = value
        return {"coverage": result.coverage,
                "explored_observable_m3": result.explored_observable_m3}


@dataclass(frozen=True)
class Mesh:
    """The reconstructed surface: `vertices` (V, 3) metres, `triangles` (T, 3) indices."""

    vertices: npt.NDArray[np.float64]
    triangles: npt.NDArray[np.int32]


class Reconstruction(Measure):
    """The TSDF's surface mesh at the end of the run (marching cubes)."""

    name = "reconstruction"

    def result(self, ep: EpisodeView, end: EpisodeEnd, done: Mapping[str, Any]) -> Mesh:
        vertices, triangles = ep.tsdf.mesh()
        return Mesh(vertices, triangles)


class SurfaceQuality(Measure):
    """Precision, recall, F-score at tau and RMSE of the reconstructed mesh's vertices against
    the truth (`sim.metrics.surface_scores`; each vertex's exact distance to the area's mesh,
    `sim.mesh_distance`)."""

    name = "surface"
    requires = ("reconstruction",)
    metrics = (
        MetricInfo("fscore", "F-score", leaderboard=True),
        MetricInfo("precision", "precision"),
        MetricInfo("recall", "recall"),
        MetricInfo("rmse_m", "RMSE", unit="m", higher_is_better=False, leaderboard=True,
                   fmt=".4f"),
    )

    def reset(self, ep: EpisodeView) -> None:
        self.truth = ep.truth.surface.sample(ep.config.final_recall_points)

    def result(self, ep: EpisodeView, end: EpisodeEnd, done: Mapping[str, Any]) -> SurfaceScores:
        mesh: Mesh = done["reconstruction"]
        return surface_scores(mesh.vertices, self.truth, ep.config.surface_tau_m,
                              ep.distance_to_surface)

    def scalars(self, value: Any) -> dict[str, float | None]:
        scores: SurfaceScores = value
        return {m.key: _finite(getattr(scores, m.key)) for m in self.metrics}


def _finite(value: float) -> float | None:
    return value if np.isfinite(value) else None
