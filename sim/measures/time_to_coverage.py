"""Time to 90 % coverage: how soon a planner has seen most of what can be seen."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from sim.measures.base import EpisodeEnd, EpisodeView, Measure, MetricInfo

THRESHOLD = 0.9


class TimeToCoverage(Measure):
    """The first sample time (every `volume_interval_s`) at which the absolute coverage (see
    `Coverage`) reaches 90 %, in seconds; None when the run never reaches it. A run that
    finished early keeps its final coverage, so it reaches 90 % then or never."""

    name = "time_to_90_coverage"
    metrics = (MetricInfo("time_to_90_coverage_s", "time to 90 %", unit="s",
                          higher_is_better=False, leaderboard=True, fmt=".0f"),)

    def reset(self, ep: EpisodeView) -> None:
        self.next = 0.0
        self.reached: float | None = None
        self.needed = THRESHOLD * ep.truth.observable_volume_m3 / ep.area.voxel_size**3
        # Kept up to date from the boxes of voxels whose state changed, not recounted over the
        # whole grid: a voxel once known stays known.
        occ = ep.mapping.occupancy
        self.changes = occ.subscribe()
        self.seen = (occ.state != 0) & ep.truth.observable
        self.count = int(np.count_nonzero(self.seen))

    def _reached_now(self, ep: EpisodeView) -> bool:
        box = self.changes.take()
        if box is not None:
            part = box.slices()
            now = (ep.mapping.occupancy.state[part] != 0) & ep.truth.observable[part]
            self.count += int(np.count_nonzero(now)) - int(np.count_nonzero(self.seen[part]))
            self.seen[part] = now
        return self.count >= self.needed

    def update(self, ep: EpisodeView, stamp: float) -> None:
        if self.reached is not None or stamp < self.next - 1e-9:
            return
        self.next += ep.config.volume_interval_s
        if self._reached_now(ep):
            self.reached = round(stamp, 6)
            self.changes.take()

    def result(self, ep: EpisodeView, end: EpisodeEnd, done: Mapping[str, Any]) -> float | None:
        if self.reached is None and end.flat_to_end and end.simulated_until < end.t_end \
                and self._reached_now(ep):
            self.reached = round(min(self.next, end.t_end), 6)  # the flat curve's next sample
        return self.reached
