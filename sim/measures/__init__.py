"""Metrics as measures: each one class, registered once (see `sim.measures.base`).

The built-in measures are registered here; a new metric is a new `Measure` subclass passed to
`register_measure` (in this list for a built-in one).
"""

from sim.measures.base import EpisodeCounters, EpisodeEnd, EpisodeView, Measure, MetricInfo
from sim.measures.counters import Collisions, PathLength, Planning, PlanningTimes, SafetyStops
from sim.measures.final import Coverage, Mesh, Reconstruction, SurfaceQuality
from sim.measures.registry import (
    UnknownMeasureError,
    make_measures,
    measure_names,
    metric_info,
    metric_infos,
    register_measure,
)
from sim.measures.series import ExploredVolume, RecallSeries, Series
from sim.measures.time_to_coverage import TimeToCoverage

for _cls in (ExploredVolume, RecallSeries, Coverage, Reconstruction, SurfaceQuality, PathLength,
             Collisions, SafetyStops, Planning, TimeToCoverage):
    register_measure(_cls)

__all__ = [
    "EpisodeCounters",
    "EpisodeEnd",
    "EpisodeView",
    "Measure",
    "Mesh",
    "MetricInfo",
    "PlanningTimes",
    "Series",
    "UnknownMeasureError",
    "make_measures",
    "measure_names",
    "metric_info",
    "metric_infos",
    "register_measure",
]
