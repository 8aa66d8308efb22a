"""`ViewpointCandidates` and `sees_into_unknown` against brute-force references on random maps:
every (eye, frontier voxel) pair made as whole arrays and filtered in turn, every face neighbour
tried in turn. They must agree exactly, order included: a planner's flights depend on the order
of its candidates."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pytest

from planners.classic import ClassicConfig
from planners.search import DistanceField
from planners.viewpoints import (
    FACES,
    ViewpointCandidates,
    Viewpoints,
    _sampled,
    lines_clear,
    ring_offsets,
    sees_into_unknown,
)
from sim.map_view import FrontierCluster, MapView
from sim.occupancy import VoxelState
from tests.planners.conftest import StackFactory


def _reference(view: MapView, clusters: list[FrontierCluster], offsets_m: npt.NDArray[np.float64],
               samples: int, max_elevation_rad: float, max_range_m: float,
               extra: npt.NDArray[np.int64] | None) -> Viewpoints:
    targets, ids = [], []
    for cluster in clusters:
        idx = cluster.indices
        pick = np.unique(np.linspace(0, len(idx) - 1, samples).astype(np.int64))
        targets.append(idx[pick])
        ids.append(np.full(len(pick), cluster.id, dtype=np.int64))
    target_idx, target_ids = np.concatenate(targets), np.concatenate(ids)
    vs = view.voxel_size
    offset_vox = offsets_m / vs
    target_c = target_idx.astype(np.float64) + 0.5
    cand_c = (target_c[:, None, :] + offset_vox[None, :, :]).reshape(-1, 3)
    tgt_c = np.repeat(target_c, len(offset_vox), axis=0)
    rep_targets = np.repeat(target_idx, len(offset_vox), axis=0)
    rep_ids = np.repeat(target_ids, len(offset_vox))
    if extra is not None:
        extra_c = extra.astype(np.float64) + 0.5
        cand_c = np.vstack([np.repeat(extra_c, len(target_c), axis=0), cand_c])
        tgt_c = np.vstack([np.tile(target_c, (len(extra_c), 1)), tgt_c])
        rep_targets = np.vstack([np.tile(target_idx, (len(extra_c), 1)), rep_targets])
        rep_ids = np.concatenate([np.tile(target_ids, len(extra_c)), rep_ids])
    keep: list[int] = []
    for r in range(len(cand_c)):
        cand = np.floor(cand_c[r]).astype(np.int64)
        if np.any(cand < 0) or np.any(cand >= np.array(view.shape)):
            continue
        if not view.traversable[tuple(cand)]:
            continue
        delta = (tgt_c[r] - cand_c[r]) * vs
        if np.arctan2(abs(delta[2]), np.linalg.norm(delta[:2])) > max_elevation_rad:
            continue
        if np.linalg.norm(delta) > max_range_m:
            continue
        keep.append(r)
    rows = np.array(keep, dtype=np.int64)
    clear = lines_clear(view.occupied, np.floor(cand_c[rows]) + 0.5, tgt_c[rows])
    rows = rows[clear]
    return Viewpoints(np.floor(cand_c[rows]).astype(np.int64), rep_targets[rows], rep_ids[rows])


def _blocks_map(make_stack: StackFactory, rng: np.random.Generator, occupied: float) -> MapView:
    """A 36 x 30 x 16 free map with `occupied` of its voxels occupied and four unknown blocks,
    so that it has frontiers of several clusters."""
    shape = (36, 30, 16)
    state = np.full(shape, VoxelState.FREE, dtype=np.uint8)
    state[rng.random(shape) < occupied] = VoxelState.OCCUPIED
    for _ in range(4):
        lo = rng.integers(0, np.array(shape) - 6)
        state[tuple(slice(a, a + int(rng.integers(3, 7))) for a in lo)] = VoxelState.UNKNOWN
    return make_stack(state, 0.1, 0.2).view()


@pytest.mark.parametrize("seed", range(6))
def test_viewpoints_match_the_brute_force_reference(make_stack: StackFactory, seed: int) -> None:
    rng = np.random.default_rng(seed)
    view = _blocks_map(make_stack, rng, 0.003)
    clusters = view.frontier_clusters(1)
    assert clusters, "the random map has no frontier"
    cfg = ClassicConfig()
    offsets = ring_offsets(cfg.view_distances_m, cfg.view_height_offsets_m, cfg.view_directions)
    extra = (np.array([[18, 15, 8], [2, 3, 4]], dtype=np.int64) if seed % 2 else None)
    args = (cfg.samples_per_cluster, np.radians(cfg.max_view_elevation_deg), 3.0)
    fast = ViewpointCandidates(view, clusters, offsets, samples_per_cluster=args[0],
                               max_elevation_rad=args[1], max_range_m=args[2],
                               extra=extra).all()
    slow = _reference(view, clusters, offsets, *args, extra)
    assert len(slow) > 200, len(slow)
    np.testing.assert_array_equal(fast.voxels, slow.voxels)
    np.testing.assert_array_equal(fast.targets, slow.targets)
    np.testing.assert_array_equal(fast.cluster_ids, slow.cluster_ids)


def _sees_reference(view: MapView, eyes: npt.NDArray[np.float64],
                    voxels: npt.NDArray[np.int64]) -> npt.NDArray[np.bool_]:
    seen = np.zeros(len(voxels), dtype=np.bool_)
    for r in range(len(voxels)):
        for face in FACES:
            nb = voxels[r] + face
            if np.any(nb < 0) or np.any(nb >= np.array(view.shape)):
                continue
            if view.state[tuple(nb)] != VoxelState.UNKNOWN:
                continue
            if lines_clear(view.occupied, eyes[r:r + 1], nb[None].astype(np.float64) + 0.5)[0]:
                seen[r] = True
                break
    return seen


@pytest.mark.parametrize("seed", range(4))
def test_sight_into_the_unknown_matches_the_brute_force_reference(make_stack: StackFactory,
                                                                  seed: int) -> None:
    rng = np.random.default_rng(100 + seed)
    shape = (30, 30, 14)
    state = np.full(shape, VoxelState.FREE, dtype=np.uint8)
    state[rng.random(shape) < 0.05] = VoxelState.OCCUPIED
    state[rng.random(shape) < 0.05] = VoxelState.UNKNOWN
    view = make_stack(state, 0.1, 0.2).view()
    voxels = np.argwhere(view.frontier)[:400].astype(np.int64)
    eyes = rng.uniform(0, np.array(shape), size=(len(voxels), 3))
    expected = _sees_reference(view, eyes, voxels)
    assert 0 < np.count_nonzero(expected) < len(expected)
    np.testing.assert_array_equal(sees_into_unknown(view, eyes, voxels), expected)


@pytest.mark.parametrize(("seed", "into_unknown"), [(0, False), (1, True), (2, True)])
def test_candidates_tested_one_eye_at_a_time_agree_with_all_tested(
        make_stack: StackFactory, seed: int, into_unknown: bool) -> None:
    """`first_at` an eye voxel is the first viewpoint of `all` standing there, and -1 exactly
    where `all` has none: the search that tests eyes as it reaches them picks what a search
    over every tested viewpoint picks."""
    rng = np.random.default_rng(200 + seed)
    view = _blocks_map(make_stack, rng, 0.006)
    cfg = ClassicConfig()
    offsets = ring_offsets(cfg.view_distances_m, cfg.view_height_offsets_m, cfg.view_directions)
    candidates = ViewpointCandidates(
        view, view.frontier_clusters(1), offsets, samples_per_cluster=cfg.samples_per_cluster,
        max_elevation_rad=np.radians(cfg.max_view_elevation_deg), max_range_m=3.0,
        into_unknown=into_unknown)
    tested = candidates.all()
    eyes = np.argwhere(candidates.eyes)
    assert len(tested) > 100 and len(eyes) > len(np.unique(tested.voxels, axis=0)), (
        "the map leaves no eye whose every candidate fails the sight test")
    for eye in eyes:
        at = np.flatnonzero(np.all(tested.voxels == eye, axis=1))
        assert candidates.accepts(eye) == (len(at) > 0)
        if len(at):
            np.testing.assert_array_equal(candidates.target_at(eye), tested.targets[at[0]])


def _sampled_reference(clusters: list[FrontierCluster], samples: int,
                       excluded: npt.NDArray[np.bool_] | None
                       ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    voxels, ids = [np.zeros((0, 3), dtype=np.int64)], [np.zeros(0, dtype=np.int64)]
    for cluster in clusters:
        idx = cluster.indices
        if excluded is not None:
            idx = idx[~excluded[tuple(idx.T)]]
        if len(idx):
            pick = np.unique(np.linspace(0, len(idx) - 1, samples).astype(np.int64))
            voxels.append(idx[pick])
            ids.append(np.full(len(pick), cluster.id))
    return np.concatenate(voxels), np.concatenate(ids)


@pytest.mark.parametrize("samples", [1, 2, 5, 16])
def test_sampled_voxels_are_the_linspace_picks_of_each_cluster(samples: int) -> None:
    """The voxels sampled from every cluster at once are, cluster by cluster, the ones
    `np.unique(np.linspace(0, n - 1, samples).astype(int))` picks from its voxels not
    excluded; clusters left empty drop out."""
    rng = np.random.default_rng(samples)
    shape = (40, 40, 10)
    excluded = rng.random(shape) < 0.3
    clusters = []
    for cid, size in enumerate([1, 2, 3, 15, 16, 17, 40, 500, 1, 7]):
        flat = np.sort(rng.choice(np.prod(shape), size, replace=False))
        indices = np.stack(np.unravel_index(flat, shape), axis=1).astype(np.int64)
        if cid == 9:
            excluded[tuple(indices.T)] = True  # wholly given up
        clusters.append(FrontierCluster(id=cid, indices=indices, centroid=np.zeros(3),
                                        normal=np.zeros(3), size=size))
    for mask in (excluded, None):
        voxels, ids = _sampled(clusters, samples, mask)
        want_voxels, want_ids = _sampled_reference(clusters, samples, mask)
        np.testing.assert_array_equal(voxels, want_voxels)
        np.testing.assert_array_equal(ids, want_ids)
    assert _sampled([], samples, None)[0].shape == (0, 3)
    assert len(_sampled(clusters[9:], samples, excluded)[1]) == 0


@pytest.mark.parametrize(("seed", "into_unknown"), [(0, False), (1, True), (2, True), (3, False)])
def test_the_compiled_search_picks_what_asking_from_python_picks(
        make_stack: StackFactory, seed: int, into_unknown: bool) -> None:
    """`DistanceField(accept=candidates)`, the eyes tested from the compiled search, finds the
    goal, the field and the path that asking `candidates.accepts` from Python finds, from every
    start, with answers remembered between the searches or not."""
    rng = np.random.default_rng(300 + seed)
    view = _blocks_map(make_stack, rng, 0.04)
    cfg = ClassicConfig()
    offsets = ring_offsets(cfg.view_distances_m, cfg.view_height_offsets_m, cfg.view_directions)

    def candidates() -> ViewpointCandidates:
        return ViewpointCandidates(
            view, view.frontier_clusters(1), offsets,
            samples_per_cluster=cfg.samples_per_cluster,
            max_elevation_rad=np.radians(cfg.max_view_elevation_deg), max_range_m=3.0,
            into_unknown=into_unknown)

    compiled, asked = candidates(), candidates()
    # Voxels with no candidate answer -1 and leave the answers kept for the eyes alone.
    for voxel in np.argwhere(~compiled.eyes)[:: max(1, int((~compiled.eyes).sum()) // 50)]:
        assert compiled.first_at(voxel) == -1
    starts = np.argwhere(view.traversable)
    turned_down = 0
    for start in starts[rng.permutation(len(starts))[:24]]:
        fast = DistanceField(view.traversable, start, 0.1, goals=compiled.eyes, accept=compiled)
        slow = DistanceField(view.traversable, start, 0.1, goals=asked.eyes,
                             accept=asked.accepts)
        alone = candidates()
        first = DistanceField(view.traversable, start, 0.1, goals=alone.eyes, accept=alone)
        plain = DistanceField(view.traversable, start, 0.1, goals=asked.eyes)
        for field in (fast, first):
            assert (field.nearest_goal is None) == (slow.nearest_goal is None)
            np.testing.assert_array_equal(field.dist_m, slow.dist_m)
        if slow.nearest_goal is None:
            continue
        goal = slow.nearest_goal
        turned_down += int(plain.nearest_goal is not None
                           and tuple(plain.nearest_goal) != tuple(goal))
        for field, cands in ((fast, compiled), (first, alone)):
            np.testing.assert_array_equal(field.nearest_goal, goal)
            np.testing.assert_array_equal(field.path_to(goal), slow.path_to(goal))
            assert field.distance_to(goal) == slow.distance_to(goal)
            np.testing.assert_array_equal(cands.target_at(goal), asked.target_at(goal))
    assert turned_down > 0, "no search turned a nearer eye down"
