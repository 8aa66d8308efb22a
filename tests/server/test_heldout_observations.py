"""A planner cannot tell the splits apart by what it is given: on a held-out area (built as a
worker builds it, `server.heldout.build_heldout_area`) it gets the same context and observation
format as on the public one, only other values (and the area's opaque name)."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from areas import load_area, load_ground_truth
from server.heldout import build_heldout_area, heldout_name, heldout_seed
from sim.config import preset
from sim.episode import run_episode
from sim.interface import Observation, Plan, PlannerContext
from sim.map_view import MapView

KEY = b"observation-format-test-key-0123"
MAP_FIELDS = ("origin", "voxel_size", "shape", "state", "free", "occupied", "traversable")


def describe(value: Any) -> Any:
    """The format of a value: types, dtypes and dimensions, not the numbers."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: describe(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, MapView):
        return {"MapView": {name: describe(getattr(value, name)) for name in MAP_FIELDS}}
    if isinstance(value, np.ndarray):
        return ("ndarray", str(value.dtype), value.ndim)
    if isinstance(value, tuple):
        return tuple(describe(v) for v in value)
    return type(value).__name__


class Spy:
    """Records what it is given (after the start-up turn in place), then ends the
    exploration."""

    def __init__(self) -> None:
        self.context: PlannerContext | None = None
        self.observations: list[Observation] = []

    def reset(self, ctx: PlannerContext) -> None:
        self.context = ctx

    def plan(self, obs: Observation) -> Plan:
        self.observations.append(obs)
        return Plan.finished("seen enough")


def _given(area: Any) -> tuple[Spy, Any]:
    spy = Spy()
    result = run_episode(area, load_ground_truth(area), spy, preset("exact"), 0, seconds=40.0)
    return spy, result


def test_a_planner_gets_the_same_format_on_either_split() -> None:
    public = load_area("maze")
    name = heldout_name(KEY, "v", 1, "maze")
    heldout = build_heldout_area(name, "maze", heldout_seed(KEY, "v", 1, "maze"))
    assert heldout.content_hash != public.content_hash  # another layout
    seen = [_given(area) for area in (public, heldout)]
    (spy_public, result_public), (spy_heldout, result_heldout) = seen
    assert spy_public.context is not None and spy_heldout.context is not None
    assert (spy_public.context.area, spy_heldout.context.area) == ("maze", name)
    assert describe(spy_public.context) == describe(spy_heldout.context)
    assert spy_public.observations and spy_heldout.observations
    assert describe(spy_public.observations[0]) == describe(spy_heldout.observations[0])
    assert spy_public.observations[0].map.shape == spy_heldout.observations[0].map.shape
    assert type(result_public) is type(result_heldout)
