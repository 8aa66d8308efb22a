"""Measures sampled over a run: explored volume and surface recall."""

from __future__ import annotations

from abc import abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from sim.measures.base import EpisodeEnd, EpisodeView, Measure
from sim.metrics import sdf_surface_recall


@dataclass(frozen=True)
class Series:
    """Samples of one quantity over simulated time: `times` (S,) s and `values` (S,)."""

    times: npt.NDArray[np.float64]
    values: npt.NDArray[np.float64]


class _Sampled(Measure):
    """A quantity sampled every `_interval(ep)` seconds from t = 0 (or from one interval)."""

    _starts_at_zero = True

    @abstractmethod
    def _interval(self, ep: EpisodeView) -> float:
        """Seconds between samples."""

    @abstractmethod
    def _sample(self, ep: EpisodeView, stamp: float) -> float:
        """The quantity now."""

    def _flat_value(self, ep: EpisodeView) -> float:
        """The value the curve keeps after an early finish."""
        return self.values[-1] if self.values else self._sample(ep, 0.0)

    def reset(self, ep: EpisodeView) -> None:
        self.period = self._interval(ep)
        self.next = 0.0 if self._starts_at_zero else self.period
        self.times: list[float] = []
        self.values: list[float] = []

    def update(self, ep: EpisodeView, stamp: float) -> None:
        if stamp >= self.next - 1e-9:
            self.times.append(round(stamp, 6))
            self.values.append(self._sample(ep, stamp))
            self.next += self.period

    def result(self, ep: EpisodeView, end: EpisodeEnd, done: Mapping[str, Any]) -> Series:
        if end.flat_to_end:
            last = self._flat_value(ep)
            while self.next <= end.t_end + 1e-9:
                self.times.append(round(self.next, 6))
                self.values.append(last)
                self.next += self.period
        return Series(np.array(self.times), np.array(self.values))


class ExploredVolume(_Sampled):
    """Known voxels (free or occupied) times the voxel volume, m³, every `volume_interval_s`.
    Reports progress to the caller as it samples."""

    name = "explored_volume"

    def _interval(self, ep: EpisodeView) -> float:
        return ep.config.volume_interval_s

    def _sample(self, ep: EpisodeView, stamp: float) -> float:
        volume = ep.mapping.occupancy.explored_volume_m3
        if ep.progress is not None:
            ep.progress(stamp, volume)
        return volume

    def _flat_value(self, ep: EpisodeView) -> float:
        # The map as the run left it: frames after the last sample may have added to it.
        return ep.mapping.occupancy.explored_volume_m3


class RecallSeries(_Sampled):
    """Surface recall read off the live TSDF (`sdf_surface_recall`) every `recall_interval_s`,
    over a fixed sample of `recall_sample_points` truth points."""

    name = "recall_series"
    _starts_at_zero = False

    def _interval(self, ep: EpisodeView) -> float:
        return ep.config.recall_interval_s

    def reset(self, ep: EpisodeView) -> None:
        super().reset(ep)
        self.points = ep.truth.surface.sample(ep.config.recall_sample_points)

    def _sample(self, ep: EpisodeView, stamp: float) -> float:
        sdf, weight = ep.tsdf.sdf_at(self.points)
        return sdf_surface_recall(sdf, weight, ep.config.surface_tau_m,
                                  ep.config.tsdf.weight_threshold)
