"""ESM's screen of failing tries (`planners.esm_screen`): the same trees and generator states as
trying every sample in Python, and never a skipped try that `_steer` would have made a node of."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt
import pytest

import planners.esm as esm_module
from planners.esm import Esm
from planners.esm_horizon import EsmHorizonPlanner, NodeIndex
from planners.esm_screen import _sample_fails_surely, skip_failing_tries
from planners.registry import make
from sim.geometry import Pose
from sim.interface import Observation, PlannerContext, PlanOutcome
from sim.map_view import MapView
from sim.occupancy import VoxelState
from tests.planners.conftest import handmade_context, stack_from_state

FloatArray = npt.NDArray[np.float64]


def _rooms(voxel: float) -> MapView:
    """A 12 x 8 x 2.5 m floor of four rooms: walls with doors, a pillar, unknown beyond the
    outer walls, mapped at `voxel` metres."""
    shape = (round(12.0 / voxel), round(8.0 / voxel), round(2.5 / voxel))
    state = np.zeros(shape, dtype=np.uint8)

    def box(lo: tuple[float, float, float], hi: tuple[float, float, float], value: int) -> None:
        a = [round(v / voxel) for v in lo]
        b = [round(v / voxel) for v in hi]
        state[a[0]:b[0], a[1]:b[1], a[2]:b[2]] = value

    box((0.5, 0.5, 0.2), (11.5, 7.5, 2.4), VoxelState.FREE)
    box((6.0, 0.5, 0.2), (6.2, 7.5, 2.4), VoxelState.OCCUPIED)  # a wall across x ...
    box((6.0, 2.0, 0.2), (6.2, 3.2, 2.2), VoxelState.FREE)  # ... with a door
    box((0.5, 4.0, 0.2), (11.5, 4.2, 2.4), VoxelState.OCCUPIED)  # a wall across y ...
    box((2.0, 4.0, 0.2), (3.2, 4.2, 2.2), VoxelState.FREE)  # ... with two doors
    box((8.5, 4.0, 0.2), (9.7, 4.2, 2.2), VoxelState.FREE)
    box((9.0, 1.5, 0.2), (9.6, 2.1, 2.4), VoxelState.OCCUPIED)  # a pillar
    return stack_from_state(state, voxel, 0.45).view()


def _context(view: MapView, seed: int) -> PlannerContext:
    ctx = handmade_context()
    return PlannerContext(**{**ctx.__dict__, "bounds_max": np.array(view.shape) * view.voxel_size,
                             "rng": np.random.default_rng(seed)})


def _fly(planner: Esm, view: MapView, calls: int) -> list[Any]:
    """A few planning calls: from the start, then half-way along each plan (in flight) and at
    its end; returns what each call returned."""
    here, yaw = np.array([1.5, 1.5, 1.2]), 0.0
    out: list[Any] = []
    plan = planner.plan(Observation(0.0, Pose(here.copy(), yaw), np.zeros(3), view,
                                    PlanOutcome.NONE))
    out.append(plan)
    t = 0.0
    for _ in range(calls):
        if plan.done or len(plan.waypoints) == 0:
            break
        end = plan.waypoints[-1]
        t += 1.0
        mid = 0.5 * (here + end[:3])
        out.append(planner.plan(Observation(t, Pose(mid, yaw), np.zeros(3), view,
                                            PlanOutcome.FLYING)))
        here, yaw = end[:3].copy(), float(end[3])
        t += 1.0
        plan = planner.plan(Observation(t, Pose(here.copy(), yaw), np.zeros(3), view,
                                        PlanOutcome.REACHED))
        out.append(plan)
    return out


def _bits(a: npt.ArrayLike) -> bytes:
    return np.ascontiguousarray(a).tobytes()


@pytest.mark.parametrize("name,voxel,seed", [
    ("esm-ipp-v1", 0.1, 0), ("esm-recon-v1", 0.1, 1), ("esm-ipp-v2", 0.1, 2),
    ("esm-ipp-v2", 0.2, 3), ("esm-ipp-v4", 0.1, 4), ("esm-recon-v4", 0.2, 5),
])
def test_screened_growth_is_the_growth_of_every_try_made(
        name: str, voxel: float, seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """The same nodes, parents, gains, plans and generator state with and without the screen,
    and the screen skips most tries."""
    view = _rooms(voxel)
    skipped: list[int] = []

    def counting(*args: Any, **kwargs: Any) -> int:
        n = skip_failing_tries(*args, **kwargs)
        skipped.append(n)
        return n

    monkeypatch.setattr(esm_module, "skip_failing_tries", counting)
    runs = []
    for screen in (True, False):
        planner = make(name)
        assert isinstance(planner, Esm)
        planner.screen_tries = screen
        ctx = _context(view, seed)
        planner.reset(ctx)
        plans = _fly(planner, view, 6)
        tree = planner.tree
        assert tree is not None
        runs.append((plans, tree, ctx.rng.bit_generator.state))
    (plans_s, tree_s, rng_s), (plans_p, tree_p, rng_p) = runs
    assert tree_s.size == tree_p.size > 5
    for field in ("positions", "parents", "yaws", "gains"):
        assert _bits(getattr(tree_s, field)) == _bits(getattr(tree_p, field)), field
    assert rng_s == rng_p
    assert len(plans_s) == len(plans_p)
    for a, b in zip(plans_s, plans_p, strict=True):
        assert _bits(a.waypoints) == _bits(b.waypoints)
        assert a.done == b.done
    tries = len(plans_s) * make(name).config.tries_per_call
    assert sum(skipped) > 0.3 * tries  # the screen did decide most tries


def _adversarial_samples(rng: np.random.Generator, positions: FloatArray, view: MapView,
                         planner: Esm) -> FloatArray:
    """Samples where `_steer`'s decisions flip: at the extension, the minimum segment and the
    density radius from nodes, on voxel faces, and uniform ones."""
    cfg = planner.config
    hi = np.array(view.shape) * view.voxel_size
    directions = rng.normal(size=(6000, 3))
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    nodes = positions[rng.integers(0, len(positions), 6000)]
    minimum = getattr(cfg, "min_segment_m", 0.0)
    at = np.concatenate([np.full(1500, cfg.extension_m), np.full(1500, max(minimum, 0.05)),
                         np.full(1500, cfg.density_radius_m),
                         rng.uniform(0.0, 2.0 * cfg.extension_m, 1500)])
    ring = nodes + at[:, None] * directions
    faces = np.round(rng.uniform(0.0, hi, size=(2000, 3)) / view.voxel_size) * view.voxel_size
    half = rng.uniform(0.0, hi, size=(2000, 3))
    half[:, 0] = np.round(half[:, 0] / view.voxel_size) * view.voxel_size
    return np.concatenate([ring, faces, half, rng.uniform(0.0, hi, size=(4000, 3))])


@pytest.mark.parametrize("name,voxel", [("esm-ipp-v1", 0.1), ("esm-ipp-v2", 0.2),
                                        ("esm-ipp-v4", 0.1)])
def test_the_screen_never_skips_a_try_steer_makes_a_node_of(name: str, voxel: float) -> None:
    view = _rooms(voxel)
    planner = make(name)
    assert isinstance(planner, Esm)
    planner.reset(_context(view, 7))
    _fly(planner, view, 1)
    tree = planner.tree
    assert tree is not None and tree.size > 5
    positions = np.ascontiguousarray(tree.positions)
    if isinstance(planner, EsmHorizonPlanner):
        planner._index = NodeIndex(positions.copy())  # as `_expand` sets it
    rule = planner._steer_rule()
    skipped = made = 0
    for sample in _adversarial_samples(np.random.default_rng(11), positions, view, planner):
        fails = _sample_fails_surely(positions, sample, rule.candidates, rule.extension_m,
                                     rule.crop_margin_m, rule.crop_min_m, rule.min_segment_m,
                                     rule.density_radius_m, view.traversable, view.origin,
                                     view.voxel_size)
        new = planner._steer(tree, view, sample)
        if fails:
            assert new is None, sample
            skipped += 1
        made += new is not None
    assert skipped > 5000 and made > 20


def test_a_try_limit_is_kept_and_the_generator_left_past_the_tries_skipped() -> None:
    """With every try failing (a root walled in), `skip_failing_tries` skips exactly the limit
    and leaves the generator where drawing those tries one at a time leaves it."""
    state = np.full((60, 40, 25), VoxelState.OCCUPIED, dtype=np.uint8)
    state[28:33, 18:23, 10:15] = VoxelState.FREE
    view = stack_from_state(state, 0.1, 0.2).view()
    root = np.array([3.05, 2.05, 1.25])
    assert view.traversable[tuple(view.world_to_index(root))]
    planner = make("esm-ipp-v1")
    assert isinstance(planner, Esm)
    rule = planner._steer_rule()
    lo, hi = np.zeros(3), np.array([6.0, 4.0, 2.5])
    for local, limit in ((0, 1), (3, 5), (10, 64), (70, 65), (15, 300)):
        rng, one_by_one = np.random.default_rng(local), np.random.default_rng(local)
        n = skip_failing_tries(rng, root[None], view, rule, root, 1.5, local, lo, hi, limit)
        assert n == limit
        for t in range(limit):
            if t < local:
                one_by_one.normal(size=3)
            else:
                one_by_one.uniform(lo, hi)
        assert rng.bit_generator.state == one_by_one.bit_generator.state
