"""The measure registry and the measures that need no flight to check."""

from __future__ import annotations

from collections.abc import Mapping
from types import SimpleNamespace
from typing import Any, cast

import numpy as np
import pytest

from sim.measures import (
    EpisodeEnd,
    EpisodeView,
    Measure,
    MetricInfo,
    UnknownMeasureError,
    measure_names,
    metric_info,
    metric_infos,
    register_measure,
)
from sim.measures import registry as measure_registry
from sim.measures.time_to_coverage import TimeToCoverage
from sim.result import RunStatus


def test_measures_follow_what_they_require() -> None:
    order = measure_names()
    assert order.index("reconstruction") < order.index("surface")
    keys = [m.key for m in metric_infos()]
    assert len(keys) == len(set(keys))
    assert {"coverage", "fscore", "rmse_m", "time_to_90_coverage_s"} <= set(keys)


def test_unknown_metric_suggests_the_closest() -> None:
    with pytest.raises(UnknownMeasureError, match="did you mean fscore"):
        metric_info("fscor")


class _Needy(Measure):
    name = "needy"
    requires = ("reconstructoin",)

    def result(self, ep: EpisodeView, end: EpisodeEnd, done: Mapping[str, Any]) -> None:
        return None


class _Clash(Measure):
    name = "clash"
    metrics = (MetricInfo("coverage", "coverage again"),)

    def result(self, ep: EpisodeView, end: EpisodeEnd, done: Mapping[str, Any]) -> None:
        return None


def test_bad_registrations_are_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(measure_registry, "_MEASURES", dict(measure_registry._MEASURES))
    with pytest.raises(ValueError, match="metric keys already reported"):
        register_measure(_Clash)
    register_measure(_Needy)
    with pytest.raises(UnknownMeasureError, match="did you mean reconstruction"):
        measure_names()


class _Occupancy:
    """The states and a subscription that reports the whole grid as changed."""

    def __init__(self, state: np.ndarray) -> None:
        self.state = state

    def subscribe(self) -> SimpleNamespace:
        box = SimpleNamespace(slices=lambda: (slice(None),) * 3)
        return SimpleNamespace(take=lambda: box)


def _view(observable: np.ndarray) -> tuple[EpisodeView, np.ndarray]:
    state = np.zeros_like(observable, dtype=np.uint8)
    ns = SimpleNamespace(
        mapping=SimpleNamespace(occupancy=_Occupancy(state)),
        truth=SimpleNamespace(observable=observable,
                              observable_volume_m3=float(observable.sum()) * 0.1**3),
        area=SimpleNamespace(voxel_size=0.1),
        config=SimpleNamespace(volume_interval_s=1.0),
    )
    return cast(EpisodeView, ns), state


def test_time_to_90_coverage_is_the_first_sample_at_90_percent() -> None:
    observable = np.zeros((10, 10, 1), dtype=bool)
    observable[:, :5] = True  # 50 observable voxels
    ep, state = _view(observable)
    measure = TimeToCoverage()
    measure.reset(ep)
    for i in range(0, 60):  # 20 Hz frames over 3 s
        stamp = i / 20.0
        if stamp >= 2.0:
            state[:9, :5] = 1  # 45 of 50 = 90 % from t = 2 s on
        state[:, 5:] = 2  # known but not observable: never counts
        measure.update(ep, stamp)
    end = EpisodeEnd(RunStatus.SUCCEEDED, 3.0, 3.0)
    assert measure.result(ep, end, {}) == 2.0
    assert measure.scalars(2.0) == {"time_to_90_coverage_s": 2.0}


def test_time_to_90_coverage_never_reached_is_none() -> None:
    observable = np.ones((10, 10, 1), dtype=bool)
    ep, state = _view(observable)
    measure = TimeToCoverage()
    measure.reset(ep)
    state[:8] = 1  # 80 %
    for i in range(40):
        measure.update(ep, i / 20.0)
    assert measure.result(ep, EpisodeEnd(RunStatus.CRASHED, 5.0, 2.0), {}) is None
    assert measure.scalars(None) == {"time_to_90_coverage_s": None}


def test_time_to_90_coverage_counts_as_a_full_recount_would() -> None:
    from sim.occupancy import OccupancyConfig, OccupancyMap

    occ = OccupancyMap(np.zeros(3), (40, 40, 10), 0.1, OccupancyConfig())
    rng = np.random.default_rng(3)
    observable = rng.random((40, 40, 10)) < 0.7
    ns = SimpleNamespace(
        mapping=SimpleNamespace(occupancy=occ),
        truth=SimpleNamespace(observable=observable,
                              observable_volume_m3=float(observable.sum()) * 0.1**3),
        area=SimpleNamespace(voxel_size=0.1), config=SimpleNamespace(volume_interval_s=1.0))
    ep = cast(EpisodeView, ns)
    measure = TimeToCoverage()
    measure.reset(ep)
    for step in range(60):
        origin = rng.uniform([0.5, 0.5, 0.2], [3.5, 3.5, 0.8])
        ends = origin + rng.normal(size=(200, 3)) * [1.5, 1.5, 0.3]
        occ.integrate(origin, ends, rng.random(200) < 0.5)
        measure.update(ep, float(step))
        if measure.reached is None:  # once reached, the measure stops counting
            assert measure.count == np.count_nonzero((occ.state != 0) & observable)
    assert measure.reached is not None
