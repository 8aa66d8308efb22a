"""Frontier and traversability trackers: incremental updates against independent references."""

from __future__ import annotations

import itertools

import numpy as np
import numpy.typing as npt
import pytest

from sim.clearance import TraversabilityTracker
from sim.frontier_pieces import touched_components
from sim.frontiers import FrontierCluster, FrontierTracker
from sim.occupancy import OccupancyMap, VoxelState

BoolGrid = npt.NDArray[np.bool_]


def reference_frontier(state: npt.NDArray[np.uint8]) -> BoolGrid:
    """FREE voxels with an UNKNOWN 6-neighbour, by shifting a padded mask."""
    unknown = np.pad(state == VoxelState.UNKNOWN, 1, constant_values=False)
    near = np.zeros(state.shape, dtype=bool)
    nx, ny, nz = state.shape
    for axis in range(3):
        for shift in (0, 2):
            window = [slice(1, nx + 1), slice(1, ny + 1), slice(1, nz + 1)]
            window[axis] = slice(shift, shift + state.shape[axis])
            near |= unknown[tuple(window)]
    return (state == VoxelState.FREE) & near


def reference_traversable(m: OccupancyMap, radius_m: float) -> BoolGrid:
    """Brute force over every offset d within the radius plus one voxel: the distance from a
    voxel centre to the cube of the voxel d away is max(|d| - 1/2, 0) per axis, and a FREE
    voxel is traversable when no non-FREE or outside voxel at an offset nearer than the radius
    exists (`sim.clearance` measures to obstacle cubes)."""
    radius = radius_m / m.voxel_size
    reach = int(np.ceil(radius)) + 1
    blocked = np.pad(m.state != VoxelState.FREE, reach, constant_values=True)
    near = np.zeros(m.shape, dtype=bool)
    nx, ny, nz = m.shape
    for d in itertools.product(range(-reach, reach + 1), repeat=3):
        gap = np.maximum(np.abs(np.array(d)) - 0.5, 0.0)
        if np.sqrt((gap**2).sum()) < radius - 1e-9:
            near |= blocked[reach + d[0]:reach + d[0] + nx, reach + d[1]:reach + d[1] + ny,
                            reach + d[2]:reach + d[2] + nz]
    return (m.state == VoxelState.FREE) & ~near


def integrate_random(m: OccupancyMap, rng: np.random.Generator, rays: int,
                     hit_share: float = 0.3) -> None:
    """One batch of rays from a random origin near the grid, `hit_share` of them hits."""
    size = np.array(m.shape) * m.voxel_size
    origin = m.origin + rng.uniform(-0.2, size + 0.2)
    direction = rng.normal(size=(rays, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    ends = origin + direction * rng.uniform(0.05, 1.5, size=(rays, 1))
    m.integrate(origin, ends, rng.random(rays) < hit_share)


def half_free_map(free_voxels: int = 5, shape: tuple[int, int, int] = (10, 10, 10),
                  axis: int = 0) -> OccupancyMap:
    """Voxels with index < free_voxels along `axis` FREE, the rest UNKNOWN."""
    m = OccupancyMap((0.0, 0.0, 0.0), shape, 0.1)
    others = [a for a in range(3) if a != axis]
    grid = np.stack(np.meshgrid(np.arange(shape[others[0]]), np.arange(shape[others[1]]),
                                indexing="ij"), axis=-1).reshape(-1, 2)
    starts = np.zeros((len(grid), 3))
    starts[:, others] = (grid + 0.5) * 0.1
    ends = starts.copy()
    starts[:, axis] = -0.5
    ends[:, axis] = (free_voxels - 0.5) * 0.1
    for start, end in zip(starts, ends, strict=True):
        m.integrate(start, end[None], [False])
    return m


def test_incremental_frontier_equals_full_recompute() -> None:
    rng = np.random.default_rng(0)
    m = OccupancyMap((-0.7, 1.1, 0.0), (40, 36, 12), 0.1)
    tracker = FrontierTracker(m)
    for _ in range(60):
        integrate_random(m, rng, int(rng.integers(1, 200)))
        tracker.update()
        expected = reference_frontier(m.state)
        np.testing.assert_array_equal(tracker.frontier, expected)
        assert tracker.count == np.count_nonzero(expected)
        # The bits the clusters list the frontier from hold the same set.
        bits = np.unpackbits(tracker._bits.view(np.uint8), bitorder="little")[:expected.size]
        np.testing.assert_array_equal(bits.astype(bool).reshape(expected.shape), expected)
    assert tracker.count > 0
    np.testing.assert_array_equal(FrontierTracker(m).frontier, tracker.frontier)
    tracker.full_recompute()
    np.testing.assert_array_equal(
        np.unpackbits(tracker._bits.view(np.uint8), bitorder="little")[:m.state.size]
        .astype(bool).reshape(m.shape), tracker.frontier)


def test_frontier_update_is_limited_to_the_dirty_box() -> None:
    m = half_free_map()
    tracker = FrontierTracker(m)
    assert tracker.update() is None
    m.integrate([0.45, 0.45, 0.45], [[0.75, 0.45, 0.45]], [False])
    region = tracker.update()
    assert region is not None
    assert (region.lo, region.hi) == ((4, 3, 3), (9, 6, 6))
    np.testing.assert_array_equal(tracker.frontier, reference_frontier(m.state))


def test_cluster_of_half_free_grid() -> None:
    m = half_free_map()
    clusters = FrontierTracker(m).clusters()
    assert len(clusters) == 1
    c = clusters[0]
    assert c.id == 0 and c.size == 100 == len(c.indices)
    assert np.all(c.indices[:, 0] == 4)
    np.testing.assert_allclose(c.centroid, [0.45, 0.5, 0.5])
    np.testing.assert_allclose(c.normal, [1.0, 0.0, 0.0])


def test_wide_clusters_are_split_near_their_voxels() -> None:
    m = half_free_map(shape=(80, 10, 10), axis=1)
    clusters = FrontierTracker(m).clusters(max_extent_m=3.0)
    assert len(clusters) == 3
    assert sum(c.size for c in clusters) == 800
    for c in clusters:
        extent = (c.indices.max(axis=0) - c.indices.min(axis=0) + 1) * m.voxel_size
        assert np.all(extent <= 3.0 + 1e-9)
        np.testing.assert_allclose(c.normal, [0.0, 1.0, 0.0])
        assert np.min(np.linalg.norm(m.index_to_world(c.indices) - c.centroid, axis=1)) < 0.1
    assert [c.id for c in clusters] == [0, 1, 2]
    xs = [c.centroid[0] for c in clusters]
    assert xs == sorted(xs)


def test_small_clusters_are_dropped_and_order_is_deterministic() -> None:
    m = OccupancyMap((0.0, 0.0, 0.0), (70, 50, 10), 0.1)
    m.integrate([0.05, 0.05, 0.05], [[0.35, 0.05, 0.05]], [False])  # 4 voxels
    m.integrate([2.05, 2.05, 0.55], [[2.05, 2.85, 0.55]], [False])  # 9 voxels
    tracker = FrontierTracker(m)
    assert [c.size for c in tracker.clusters(min_size=5)] == [9]
    assert [c.size for c in tracker.clusters(min_size=1)] == [4, 9]
    rng = np.random.default_rng(1)
    for _ in range(10):
        integrate_random(m, rng, 100)
    first = tracker.clusters()
    second = tracker.clusters()
    assert len(first) == len(second) > 1
    for a, b in zip(first, second, strict=True):
        assert a.id == b.id
        np.testing.assert_array_equal(a.indices, b.indices)
    keys = [tuple(c.indices[0]) for c in first]
    assert keys == sorted(keys)
    covered = np.concatenate([c.indices for c in tracker.clusters(min_size=1)])
    assert len(covered) == tracker.count
    assert np.all(tracker.frontier[tuple(covered.T)])


def _assert_same_clusters(got: list[FrontierCluster], expected: list[FrontierCluster]) -> None:
    assert len(got) == len(expected)
    for a, b in zip(got, expected, strict=True):
        assert a.id == b.id and a.size == b.size
        np.testing.assert_array_equal(a.indices, b.indices)
        # Bit for bit: the same sums over the same voxels in the same order.
        assert a.centroid.tobytes() == b.centroid.tobytes()
        assert a.normal.tobytes() == b.normal.tobytes()


@pytest.mark.parametrize("seed", range(4))
def test_clusters_kept_between_calls_are_those_made_from_scratch(seed: int) -> None:
    """The pieces a tracker keeps from call to call, made again only for the components the
    map's changes touched, give the clusters of a fresh tracker on the same map, to the bit:
    through small and large changes, calls with nothing changed, changes seen by `update`
    calls between the clusters calls, other sizes and another cut (which makes them anew)."""
    rng = np.random.default_rng(seed)
    m = OccupancyMap((0.2, -0.4, 0.0), (60, 48, 14), 0.1)
    tracker = FrontierTracker(m)
    assert tracker.clusters() == []
    reused = 0
    for step in range(40):
        # Mostly small batches far apart (most components untouched), now and then a large one.
        rays = int(rng.integers(400, 900)) if step % 9 == 4 else int(rng.integers(1, 60))
        integrate_random(m, rng, rays, hit_share=float(rng.uniform(0.0, 0.5)))
        if step % 5 == 2:
            tracker.update()  # the change is recomputed before the clusters are asked for
            integrate_random(m, rng, int(rng.integers(1, 30)))
        before = tracker._pieces
        cut = 0.9 if step % 13 == 12 else 0.6
        min_size = (1, 3, 5)[step % 3]
        got = tracker.clusters(min_size=min_size, max_extent_m=cut)
        if before is not None and before.cell_voxels == tracker._pieces.cell_voxels:
            reused += 1
        _assert_same_clusters(got, FrontierTracker(m).clusters(min_size, cut))
        if step % 7 == 3:  # nothing changed since
            _assert_same_clusters(tracker.clusters(min_size, cut), got)
    assert reused > 20


def test_a_failed_clusters_call_leaves_the_next_to_start_again(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A call that fails while making the pieces again (out of memory, say) keeps no pieces:
    the next call gives the clusters of the map as it is, not those of the call before; and
    a cluster's centroid and normal are the caller's own (changing them changes nothing the
    tracker keeps)."""
    import sim.frontiers

    rng = np.random.default_rng(5)
    m = OccupancyMap((0.0, 0.0, 0.0), (40, 40, 10), 0.1)
    tracker = FrontierTracker(m)
    for _ in range(5):
        integrate_random(m, rng, 40)
    before = tracker.clusters(min_size=1, max_extent_m=0.6)
    before[0].centroid[:] = -1.0
    before[0].normal[:] = 0.0
    integrate_random(m, rng, 300)

    def failing(*args: object) -> None:
        raise MemoryError

    monkeypatch.setattr(sim.frontiers, "merged", failing)
    monkeypatch.setattr(sim.frontiers, "pieces_of", failing)
    with pytest.raises(MemoryError):
        tracker.clusters(min_size=1, max_extent_m=0.6)
    monkeypatch.undo()
    _assert_same_clusters(tracker.clusters(min_size=1, max_extent_m=0.6),
                          FrontierTracker(m).clusters(1, 0.6))


def test_a_component_is_touched_by_a_region_within_one_voxel_of_its_box() -> None:
    """`touched_components`: a region meeting a component's box grown by one voxel touches it
    (a voxel there may join it), one farther does not; the region is half-open."""
    from sim.frontier_pieces import pieces_of
    from sim.occupancy import IndexBox

    m = half_free_map(free_voxels=3, shape=(12, 12, 12))  # one component: the plane x = 2
    indices = np.argwhere(reference_frontier(m.state)).astype(np.int64)
    pieces = pieces_of(indices, m.shape, m.state, m.origin, m.voxel_size, 100.0)
    assert pieces.comp_lo.tolist() == [[2, 0, 0]] and pieces.comp_hi.tolist() == [[2, 11, 11]]
    for lo, hi, touched in (((3, 0, 0), (4, 1, 1), True),    # beside the plane
                            ((4, 0, 0), (5, 1, 1), False),   # two voxels off
                            ((1, 11, 11), (2, 12, 12), True),  # beside it, below
                            ((0, 0, 0), (1, 12, 12), False),  # two voxels below
                            ((5, 5, 5), (5, 9, 9), False)):  # empty
        region = IndexBox(lo, hi)
        got = bool(touched_components(pieces, region)[0]) if region.size else False
        assert got == touched, (lo, hi)


def test_free_voxel_next_to_unknown_is_not_traversable() -> None:
    m = half_free_map()
    trav = TraversabilityTracker(m, radius_m=0.25).traversable
    assert m.state[4, 5, 5] == VoxelState.FREE and m.state[5, 5, 5] == VoxelState.UNKNOWN
    assert not trav[4, 5, 5]
    # A centre exactly 0.25 m from the unknown voxels' cubes and from the grid's faces still
    # fits (clearance is measured to obstacle cubes; 0.3 m no longer fits in 0.5 m of free space).
    assert not TraversabilityTracker(m, radius_m=0.3).traversable.any()
    expected = np.zeros(m.shape, dtype=bool)
    expected[2, 2:8, 2:8] = True
    np.testing.assert_array_equal(trav, expected)
    np.testing.assert_array_equal(TraversabilityTracker(m, radius_m=0.0).traversable,
                                  m.state == VoxelState.FREE)


@pytest.mark.parametrize("radius_m", [0.1, 0.25, 0.3])
def test_incremental_traversability_equals_full_recompute(radius_m: float) -> None:
    rng = np.random.default_rng(2)
    m = OccupancyMap((0.3, -0.2, 0.0), (36, 30, 12), 0.1)
    tracker = TraversabilityTracker(m, radius_m)
    for _ in range(40):
        # Few hits: a return stays until a ray through it contradicts it, and open space must
        # remain at the largest radius.
        integrate_random(m, rng, int(rng.integers(50, 400)), hit_share=0.003)
        tracker.update()
        np.testing.assert_array_equal(tracker.traversable, reference_traversable(m, radius_m))
    assert tracker.traversable.any()
    fresh = TraversabilityTracker(m, radius_m)
    np.testing.assert_array_equal(fresh.traversable, tracker.traversable)
    tracker.full_recompute()
    np.testing.assert_array_equal(fresh.traversable, tracker.traversable)


def test_trackers_share_the_map_at_their_own_pace() -> None:
    rng = np.random.default_rng(3)
    m = OccupancyMap((0.0, 0.0, 0.0), (32, 32, 10), 0.1)
    frontiers = FrontierTracker(m)
    clearance = TraversabilityTracker(m, 0.2)
    for step in range(30):
        integrate_random(m, rng, 150)
        frontiers.update()
        np.testing.assert_array_equal(frontiers.frontier, reference_frontier(m.state))
        if step % 4 == 3:
            clearance.update()
            np.testing.assert_array_equal(clearance.traversable, reference_traversable(m, 0.2))


def test_components_are_scipys_26_connected_labels_numbered_in_c_order() -> None:
    """`_joined` over the pairs of `_pairs_and_components` joins 26-neighbours with equal keys
    (pairs found from the 13 neighbours before each voxel): the components of scipy's labelling
    of each key's voxels, numbered by their first voxel in C order, in grids with voxels on
    every face (where a neighbour's flat index wraps into the next row or plane). The
    components `_pairs_and_components` joins as it finds the pairs are `_joined`'s with one key
    for all."""
    from scipy import ndimage

    from sim.frontier_pieces import _joined, _pairs_and_components

    rng = np.random.default_rng(0)
    shapes = [(30, 25, 12), (1, 9, 7), (8, 1, 6), (7, 9, 1), (2, 2, 2), (12, 3, 40)]
    for trial in range(24):
        shape = shapes[trial % len(shapes)]
        mask = rng.random(shape) < rng.uniform(0.05, 0.9)
        indices = np.argwhere(mask).astype(np.int64)
        keys = (rng.integers(0, 3, len(indices)) if trial % 2
                else np.zeros(len(indices))).astype(np.int64)
        pairs, components, count = _pairs_and_components(indices, shape[1], shape[2])
        one_key = _joined(pairs, np.zeros(len(indices), dtype=np.int64), len(indices))
        np.testing.assert_array_equal(components, one_key[0])
        assert count == one_key[1]
        labels, n = _joined(pairs, keys, len(indices))
        component = np.empty(len(indices), dtype=np.int64)
        offset = 0
        for value in np.unique(keys):
            chosen = keys == value
            grid = np.zeros(shape, dtype=bool)
            grid[tuple(indices[chosen].T)] = True
            labelled, count = ndimage.label(grid, structure=np.ones((3, 3, 3)))
            component[chosen] = labelled[tuple(indices[chosen].T)] + offset
            offset += count + 1
        _, first, inverse = np.unique(component, return_index=True, return_inverse=True)
        expected = np.argsort(np.argsort(first))[inverse]
        np.testing.assert_array_equal(labels, expected)
        assert n == len(first)


def test_grouped_is_a_stable_sort_by_label() -> None:
    """`_grouped` places the voxels by counting: NumPy's stable argsort by label, with labels
    of no voxel, one label for all and one voxel per label."""
    from sim.frontier_pieces import _grouped

    rng = np.random.default_rng(7)
    for count, n in ((0, 3), (1, 1), (500, 1), (500, 40), (2_000, 700), (300, 300)):
        indices = rng.integers(0, 50, size=(count, 3)).astype(np.int64)
        labels = (rng.permutation(count) % n if count == n
                  else rng.integers(0, n, size=count)).astype(np.int64)
        sizes = np.bincount(labels, minlength=n)
        np.testing.assert_array_equal(_grouped(indices, labels, sizes),
                                      indices[np.argsort(labels, kind="stable")])


def test_cell_keys_cut_each_component_box_into_equal_cells() -> None:
    """`_cell_keys` gives each voxel its component's cell: the box cut into the fewest equal
    cells at most `cell_voxels` wide, keys distinct across components."""
    from sim.frontier_pieces import _cell_keys, _label_boxes

    rng = np.random.default_rng(4)
    indices = rng.integers(0, 60, size=(5_000, 3)).astype(np.int64)
    labels = rng.integers(0, 7, size=5_000).astype(np.int64)
    keys = _cell_keys(indices, labels, *_label_boxes(indices, labels, 7), 12.5)
    for label in range(7):
        mine = labels == label
        lo, hi = indices[mine].min(axis=0), indices[mine].max(axis=0)
        extent = hi - lo + 1
        cells = np.maximum(np.ceil(extent / 12.5 - 1e-9), 1).astype(np.int64)
        cell = ((indices[mine] - lo) * cells) // extent
        assert (cell < cells).all() and (np.ceil(extent / cells) <= 13).all()
        local = (cell[:, 0] * cells[1] + cell[:, 1]) * cells[2] + cell[:, 2]
        # Keys are one-to-one with (component, cell).
        pairs = {(int(k), int(c)) for k, c in zip(keys[mine], local, strict=True)}
        assert len(pairs) == len({k for k, _ in pairs}) == len({c for _, c in pairs})
    assert len(set(keys[labels == 0]) & set(keys[labels == 1])) == 0


@pytest.mark.parametrize("shape", [(30, 25, 12), (7, 3, 5), (1, 1, 3), (9, 9, 8), (5, 4, 33)])
def test_true_indices_are_numpys_argwhere(shape: tuple[int, int, int]) -> None:
    """`_true_indices` (64 voxels read at a time, only their set bits visited) lists the set
    voxels in C order, grids whose size is not a multiple of 64 and voxels in the last,
    partial word included, as do every bit of a word and none."""
    from sim.frontiers import _true_indices

    rng = np.random.default_rng(len(shape) + shape[0])
    for density in (0.0, 0.01, 0.3, 1.0):
        mask = rng.random(shape) < density
        mask.reshape(-1)[-1] = density > 0.0
        flat = np.zeros(-(-mask.size // 64) * 64, dtype=bool)
        flat[:mask.size] = mask.reshape(-1)
        bits = np.packbits(flat, bitorder="little").view(np.uint64)
        got = _true_indices(bits, shape[1], shape[2], int(np.count_nonzero(mask)))
        np.testing.assert_array_equal(got, np.argwhere(mask))
