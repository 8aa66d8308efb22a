"""esm-ipp-v4 / esm-recon-v4: the tree grows in the calls made in flight, a segment's end only
selects, on a hand-made map."""

from __future__ import annotations

import numpy as np
import pytest

from planners.esm_continuous import EsmContinuous
from planners.esm_horizon import EsmHorizonPlanner
from planners.registry import make, spec
from sim.geometry import Pose
from sim.interface import Observation, PlanOutcome
from sim.map_view import MapView
from tests.planners.conftest import handmade_context, open_box_view


def _obs(view: MapView, here: np.ndarray, outcome: PlanOutcome, time: float) -> Observation:
    return Observation(time, Pose(here.copy(), 0.0), np.zeros(3), view, outcome)


@pytest.mark.parametrize("name", ["esm-ipp-v4", "esm-recon-v4"])
def test_registered_as_v3_with_their_gains(name: str) -> None:
    planner = make(name)
    assert isinstance(planner, EsmContinuous)
    assert planner.config.gain == ("volumetric" if name.startswith("esm-ipp") else
                                   "reconstruction")
    assert planner.config.first_growth_s == 0.1
    assert spec(name).id == name
    assert spec(name.rsplit("-", 1)[0]).id == name  # the default: the newest original version


def test_flight_grows_the_tree_and_the_segment_end_only_selects() -> None:
    view = open_box_view()
    # Three segments per batch, so that the small box is not filled by the first call.
    planner = make("esm-ipp-v4", {"new_per_call": 3})
    assert isinstance(planner, EsmContinuous)
    planner.reset(handmade_context())
    here = np.array([2.0, 1.5, 1.25])
    first = planner.plan(_obs(view, here, PlanOutcome.NONE, 0.0))
    # The first call has a lone root: it grows, as v3, and asks to be called once the flight
    # is under way.
    assert not first.done and first.replan_s == 0.1 and first.info["added"] > 0
    tree = planner.tree
    assert tree is not None
    target = first.waypoints[-1, :3].copy()
    # In flight: one batch of growth, the samples drawn round the node flown to.
    pending = planner._pending
    assert pending >= 0
    np.testing.assert_array_equal(planner._sampling_centre(tree), tree.positions[pending])
    before = tree.size
    midway = (here + target) / 2.0
    grow = planner.plan(_obs(view, midway, PlanOutcome.FLYING, 0.6))
    assert grow.keep and grow.replan_s is None and grow.info["mode"] == "grow"
    assert grow.info["added"] == tree.size - before > 0
    assert grow.waypoints.shape == (0, 4)
    # At the segment's end a branch is worth flying: nothing is added, a segment is flown.
    reached = planner.plan(_obs(view, target, PlanOutcome.REACHED, 2.0))
    assert not reached.done and not reached.keep and reached.replan_s == 0.1
    assert reached.info["added"] == 0 and reached.info["mode"] == "tree"


def test_v3_grows_at_every_segment_end_where_v4_does_not() -> None:
    """The same first call and flight for both; at the segment's end v3 grows the tree."""
    added = {}
    for name in ("esm-ipp-v3", "esm-ipp-v4"):
        view = open_box_view()
        planner = make(name, {"new_per_call": 3})
        assert isinstance(planner, EsmHorizonPlanner)
        planner.reset(handmade_context())
        here = np.array([2.0, 1.5, 1.25])
        first = planner.plan(_obs(view, here, PlanOutcome.NONE, 0.0))
        assert first.replan_s == (None if name.endswith("v3") else 0.1)
        reached = planner.plan(_obs(view, first.waypoints[-1, :3], PlanOutcome.REACHED, 2.0))
        added[name] = reached.info["added"]
    assert added["esm-ipp-v3"] > 0 and added["esm-ipp-v4"] == 0


def test_a_call_in_flight_before_any_tree_keeps_flying() -> None:
    planner = make("esm-recon-v4")
    planner.reset(handmade_context())
    plan = planner.plan(_obs(open_box_view(), np.array([2.0, 1.5, 1.25]), PlanOutcome.FLYING, 0.0))
    assert plan.keep and plan.replan_s is None and plan.info["added"] == 0
