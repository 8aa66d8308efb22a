"""esm-ipp-v2 / esm-recon-v2 and their v3: the local gain horizon, the minimum segment length, the
large-area tree and the k-d tree of nodes, on hand-made maps and trees."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import pytest

from planners.esm_config import EsmConfig
from planners.esm_horizon import EsmHorizon, NodeIndex
from planners.esm_horizon_config import EsmHorizonConfig, EsmHorizonV3Config, EsmLargeArea
from planners.registry import make, spec
from planners.segment_tree import FlightTime, SegmentTree
from sim.geometry import Pose
from sim.interface import Observation, PlannerContext, PlanOutcome
from sim.map_view import MapView
from sim.occupancy import VoxelState
from tests.planners.conftest import handmade_context, open_box_view, stack_from_state

FloatArray = npt.NDArray[np.float64]
FLIGHT = FlightTime(v_max=1.5, a_max=2.5, yaw_rate_max=1.0, yaw_acc_max=2.0)



def test_registered_beside_v1_with_their_gains() -> None:
    assert spec("esm-ipp-v3").id == "esm-ipp-v3"
    assert spec("esm-recon-v3").id == "esm-recon-v3"
    for version in (2, 3):
        assert make(f"esm-ipp-v{version}").config.gain == "volumetric"  # type: ignore[attr-defined]
        assert make(f"esm-recon-v{version}").config.gain == \
            "reconstruction"  # type: ignore[attr-defined]
    assert type(make("esm-ipp-v1")).__name__ == "EsmV1"


def test_the_large_area_tree_applies_on_coarse_maps_only() -> None:
    cfg = EsmHorizonConfig()
    indoor = cfg.for_area(0.1, indoor=True)
    assert indoor == cfg
    # Indoors the tree is the authors' exploration configuration, as in v1.
    v1 = EsmConfig()
    assert (indoor.extension_m, indoor.density_radius_m, indoor.local_count) == \
        (v1.extension_m, v1.density_radius_m, v1.local_count)
    large = cfg.for_area(0.2, indoor=True)
    for key, value in EsmLargeArea().model_dump().items():
        assert getattr(large, key) == value
    assert large.extension_m == 3.0 and large.update_range_m == 6.0
    assert large.gain == cfg.gain and large.min_value == cfg.min_value  # the rest is kept
    assert EsmHorizonConfig(profile="indoor").for_area(0.2, True).extension_m == v1.extension_m
    assert EsmHorizonConfig(profile="large").for_area(0.1, True).extension_m == 3.0
    assert EsmHorizonConfig(large_area_voxel_m=None).for_area(0.4, True).extension_m == 1.5
    # v2 tells areas apart by their voxel size alone.
    assert cfg.for_area(0.1, indoor=False) == cfg


def test_v3_grows_the_large_area_tree_outdoors_at_any_voxel_size() -> None:
    cfg = EsmHorizonV3Config()
    assert cfg.for_area(0.1, indoor=True).extension_m == 1.5
    assert cfg.for_area(0.1, indoor=False).extension_m == 3.0
    assert cfg.for_area(0.2, indoor=True).extension_m == 3.0
    assert EsmHorizonV3Config(large_outdoors=False).for_area(0.1, indoor=False).extension_m == 1.5
    assert EsmHorizonV3Config(profile="indoor").for_area(0.2, indoor=False).extension_m == 1.5
    # Beyond the tree, v3 is v2.
    v2 = EsmHorizonConfig().model_dump()
    assert {k: v for k, v in cfg.model_dump().items() if k != "large_outdoors"} == v2


@pytest.mark.parametrize(("name", "indoor", "extension"), [
    ("esm-ipp-v2", False, 1.5), ("esm-ipp-v3", True, 1.5), ("esm-ipp-v3", False, 3.0),
    ("esm-recon-v3", False, 3.0),
])
def test_the_planner_reads_the_area_class_from_its_context(name: str, indoor: bool,
                                                            extension: float) -> None:
    planner = make(name)
    planner.reset(handmade_context(indoor))
    here = np.array([2.0, 2.0, 1.25])
    planner.plan(Observation(0.0, Pose(here, 0.0), np.zeros(3), open_box_view(), PlanOutcome.NONE))
    assert planner.config.extension_m == extension  # type: ignore[attr-defined]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_node_index_finds_the_nearest_nodes_also_among_those_added_since(seed: int) -> None:
    rng = np.random.default_rng(seed)
    positions = rng.uniform(0.0, 10.0, (200, 3))
    index = NodeIndex(positions)
    grown = np.vstack([positions, rng.uniform(0.0, 10.0, (15, 3))])
    for point in rng.uniform(-2.0, 12.0, (30, 3)):
        d = np.linalg.norm(grown - point, axis=1)
        found = index.nearest(grown, point, 4)
        np.testing.assert_allclose(d[found], np.sort(d)[:4])
        assert index.min_distance(grown, point) == pytest.approx(d.min())
    empty = NodeIndex(np.zeros((0, 3)))
    assert empty.min_distance(np.zeros((0, 3)), np.zeros(3)) == math.inf


class _CountingHorizon(EsmHorizon):
    """Gains from a table; records which nodes were recomputed."""

    def __init__(self, truth: dict[int, float], update_range_m: float | None) -> None:
        super().__init__(EsmHorizonConfig(update_range_m=update_range_m))
        self.truth = truth
        self.evaluated: list[int] = []

    def refresh(self, tree: SegmentTree, view: MapView, node: int, now: float) -> None:
        self.evaluated.append(node)
        tree.gains[node] = self.truth[node]
        tree.stamps[node] = now


def _line_tree() -> SegmentTree:
    """A root at x = 0 and two branches along x: one near (1, 2 m), one far (1 m steps to
    10 m) whose tip had a large gain when it was last computed."""
    tree = SegmentTree(np.zeros(3))
    near = tree.add(np.array([-1.0, 0.0, 0.0]), tree.root, 0.0, 1.0, gain=1.0, stamp=0.0)
    tree.add(np.array([-2.0, 0.0, 0.0]), near, 0.0, 1.0, gain=1.0, stamp=0.0)
    parent = tree.root
    for x in range(1, 11):
        parent = tree.add(np.array([float(x), 0.0, 0.0]), parent, 0.0, 1.0,
                          gain=50.0 if x == 10 else 0.5, stamp=0.0)
    return tree


def test_only_gains_within_the_update_range_are_recomputed() -> None:
    tree = _line_tree()
    truth = {n: 0.0 for n in range(tree.size)}  # everything has been seen since
    planner = _CountingHorizon(truth, update_range_m=3.0)
    child, value = planner.select(tree, None, now=1.0)  # type: ignore[arg-type]
    far = np.linalg.norm(tree.positions, axis=1) > 3.0
    assert planner.evaluated, "nothing was recomputed: the test tests nothing"
    assert not far[planner.evaluated].any()
    # The far tip keeps its stale gain, so the far branch is still chosen (the original).
    assert tree.positions[child][0] == 1.0
    assert value > 0.0
    # Without a horizon (v1's rule) the far tip is recomputed and nothing is left worth it.
    planner = _CountingHorizon(dict(truth), update_range_m=None)
    tree = _line_tree()
    _, value = planner.select(tree, None, now=1.0)  # type: ignore[arg-type]
    assert far[planner.evaluated].any()
    assert value == 0.0



def test_no_new_segment_is_shorter_than_the_minimum() -> None:
    view = open_box_view()
    planner = make("esm-ipp-v2", {"min_segment_m": 1.0})
    assert isinstance(planner, EsmHorizon)
    planner.reset(handmade_context())
    start = np.array([2.0, 2.0, 1.25])
    assert planner._crop(view, start, start + np.array([0.8, 0.0, 0.0])) is None
    new = planner._crop(view, start, start + np.array([1.2, 0.0, 0.0]))
    assert new is not None
    np.testing.assert_allclose(new, start + np.array([1.2, 0.0, 0.0]))


def test_a_flight_grows_a_tree_of_long_segments_on_a_coarse_map() -> None:
    """On a 0.2 m map the large-area tree: every segment made while growing is at least
    `min_segment_m` long and nodes keep `density_radius_m` apart."""
    state = np.zeros((60, 40, 25), dtype=np.uint8)
    state[5:55, 5:35, 3:22] = VoxelState.FREE
    view = stack_from_state(state, 0.2, 0.45).view()
    planner = make("esm-ipp-v2")
    assert isinstance(planner, EsmHorizon)
    ctx = handmade_context()
    planner.reset(PlannerContext(**{**ctx.__dict__, "bounds_max": np.array(state.shape) * 0.2}))
    here = np.array([5.1, 4.1, 2.5])
    plan = planner.plan(Observation(0.0, Pose(here.copy(), 0.0), np.zeros(3), view,
                                    PlanOutcome.NONE))
    assert not plan.done
    tree = planner.tree
    assert tree is not None and tree.size > 5
    assert planner.config.extension_m == 3.0
    kids = np.flatnonzero(tree.parents >= 0)
    lengths = np.linalg.norm(tree.positions[kids] - tree.positions[tree.parents[kids]], axis=1)
    assert lengths.min() >= 2.5 - 1e-9 and lengths.max() <= 3.0 + 1e-9
    d = np.linalg.norm(tree.positions[:, None] - tree.positions[None], axis=2)
    np.fill_diagonal(d, np.inf)
    assert d.min() >= 2.0 - 1e-9
