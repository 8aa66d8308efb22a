"""Candidate viewpoints around frontier voxels, shared by frontier-driven planners.

A viewpoint is a traversable voxel from which the level camera can see a frontier voxel: within a
horizontal ring around it, inside the vertical field of view, with no occupied voxel on the line
of sight (unknown voxels on it may well be free: sensor noise leaves such holes). With
`into_unknown`, the line of sight to one of the frontier voxel's unknown face neighbours must be
clear as well: seeing a free voxel clears nothing, seeing into the unknown beside it does.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
import numpy.typing as npt

from planners.search import BoolGrid, CompiledAccept, HeapArray, IndexArray, resume_search
from sim.map_view import FrontierCluster, MapView
from sim.occupancy import VoxelState

_UNKNOWN = int(VoxelState.UNKNOWN)
_OCCUPIED = int(VoxelState.OCCUPIED)

FACES = np.array([(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)],
                 dtype=np.int64)


@dataclass(frozen=True)
class Viewpoints:
    """Candidate viewpoints.

    Attributes:
        voxels: (M, 3) int64 traversable voxels to stand in.
        targets: (M, 3) int64 the frontier voxel each one looks at.
        cluster_ids: (M,) int64 the cluster of that frontier voxel.
    """

    voxels: IndexArray
    targets: IndexArray
    cluster_ids: npt.NDArray[np.int64]

    def __len__(self) -> int:
        return len(self.voxels)


@numba.njit(cache=True)
def _line_clear(grid: npt.NDArray[np.bool_] | npt.NDArray[np.uint8], blocked: int,
                a: npt.NDArray[np.float64], b: npt.NDArray[np.float64]) -> bool:
    """Whether no voxel strictly between the end voxels of a→b (voxel units) holds `blocked`
    in `grid`: True in a mask, or a `VoxelState` in the map's state grid (read in place; a
    mask of it made per call cost more than the lines on the large areas)."""
    ai, aj, ak = int(np.floor(a[0])), int(np.floor(a[1])), int(np.floor(a[2]))
    bi, bj, bk = int(np.floor(b[0])), int(np.floor(b[1])), int(np.floor(b[2]))
    length = np.sqrt(np.sum((b - a) ** 2))
    steps = max(1, int(np.ceil(length * 4.0)))
    for s in range(1, steps):
        t = s / steps
        i = int(np.floor(a[0] + (b[0] - a[0]) * t))
        j = int(np.floor(a[1] + (b[1] - a[1]) * t))
        k = int(np.floor(a[2] + (b[2] - a[2]) * t))
        if (i == ai and j == aj and k == ak) or (i == bi and j == bj and k == bk):
            continue
        if grid[i, j, k] == blocked:
            return False
    return True


@numba.njit(cache=True)
def _lines_clear_of(grid: npt.NDArray[np.bool_] | npt.NDArray[np.uint8], blocked: int,
                    a: npt.NDArray[np.float64],
                    b: npt.NDArray[np.float64]) -> npt.NDArray[np.bool_]:
    """`lines_clear` where the voxels holding `blocked` in `grid` block."""
    out = np.ones(a.shape[0], dtype=np.bool_)
    for r in range(a.shape[0]):
        out[r] = _line_clear(grid, blocked, a[r], b[r])
    return out


@numba.njit(cache=True)
def lines_clear(
    blocked: BoolGrid, a: npt.NDArray[np.float64], b: npt.NDArray[np.float64]
) -> npt.NDArray[np.bool_]:
    """For each pair a[i]→b[i] (voxel units), whether no voxel strictly between the two end
    voxels is blocked."""
    return _lines_clear_of(blocked, True, a, b)


@numba.njit(cache=True)
def _sees_one(state: npt.NDArray[np.uint8], eye: npt.NDArray[np.float64],
              voxel: npt.NDArray[np.int64]) -> bool:
    """Whether the line of sight from `eye` to an unknown face neighbour of `voxel` crosses no
    occupied voxel (`state`: the map's (nx, ny, nz) `VoxelState`)."""
    si, sj, sk = state.shape
    end = np.empty(3, dtype=np.float64)
    for f in range(FACES.shape[0]):
        i = voxel[0] + FACES[f, 0]
        j = voxel[1] + FACES[f, 1]
        k = voxel[2] + FACES[f, 2]
        if not (0 <= i < si and 0 <= j < sj and 0 <= k < sk) or state[i, j, k] != _UNKNOWN:
            continue
        end[0], end[1], end[2] = i + 0.5, j + 0.5, k + 0.5
        if _line_clear(state, _OCCUPIED, eye, end):
            return True
    return False


@numba.njit(cache=True)
def _sees_into_unknown(state: npt.NDArray[np.uint8], eyes: npt.NDArray[np.float64],
                       voxels: npt.NDArray[np.int64]) -> npt.NDArray[np.bool_]:
    seen = np.zeros(voxels.shape[0], dtype=np.bool_)
    for r in range(voxels.shape[0]):
        seen[r] = _sees_one(state, eyes[r], voxels[r])
    return seen


@numba.njit(cache=True)
def _first_in_sight(state: npt.NDArray[np.uint8], into_unknown: bool,
                    eyes: npt.NDArray[np.int64],
                    targets: npt.NDArray[np.int64], pair_t: npt.NDArray[np.int64],
                    rows: npt.NDArray[np.int64]) -> int:
    """The first of `rows` whose line of sight from its eye voxel's centre to its target
    voxel's centre (`targets[pair_t[r]]`) is clear (and, with `into_unknown`, whose eye sees
    into the unknown beside the target); -1 if none."""
    eye = np.empty(3, dtype=np.float64)
    aim = np.empty(3, dtype=np.float64)
    for r in rows:
        t = pair_t[r]
        for a in range(3):
            eye[a] = eyes[r, a] + 0.5
            aim[a] = targets[t, a] + 0.5
        if not _line_clear(state, _OCCUPIED, eye, aim):
            continue
        if into_unknown and not _sees_one(state, eye, targets[t]):
            continue
        return r
    return -1


@numba.njit(cache=True)
def _first_at(flat: int, state: npt.NDArray[np.uint8], into_unknown: bool,
              eyes: npt.NDArray[np.int64], targets: npt.NDArray[np.int64],
              pair_t: npt.NDArray[np.int64], by_eye: npt.NDArray[np.int64],
              first: npt.NDArray[np.int64]) -> int:
    """`_first_in_sight` over the candidates at eye voxel `flat` (the rows `by_eye` lists for
    it), remembered in `first` at the group's first position (-2: not yet asked)."""
    n = max(eyes.shape[0], 1)
    lo = np.searchsorted(by_eye, flat * n)
    hi = np.searchsorted(by_eye, (flat + 1) * n)
    if lo == hi:
        return -1
    if first[lo] == -2:
        first[lo] = _first_in_sight(state, into_unknown, eyes, targets, pair_t, by_eye[lo:hi] % n)
    return first[lo]


@numba.njit(cache=True)
def _nearest_in_sight(
    passable: BoolGrid, goals: BoolGrid, max_cost: float, dist: npt.NDArray[np.float64],
    parent: npt.NDArray[np.int64], done: npt.NDArray[np.bool_], touched: npt.NDArray[np.int64],
    n_touched: int, heap: HeapArray, size: int, state: npt.NDArray[np.uint8],
    into_unknown: bool, eyes: npt.NDArray[np.int64], targets: npt.NDArray[np.int64],
    pair_t: npt.NDArray[np.int64], by_eye: npt.NDArray[np.int64], first: npt.NDArray[np.int64],
) -> tuple[int, npt.NDArray[np.int64], int, HeapArray, int]:
    """The search run on to the first eye voxel with a candidate in sight (`CompiledAccept`)."""
    goal = -1
    while True:
        goal, touched, n_touched, heap, size = resume_search(
            passable, goals, max_cost, dist, parent, done, touched, n_touched, heap, size, goal)
        if goal < 0 or _first_at(goal, state, into_unknown, eyes, targets, pair_t, by_eye,
                                 first) >= 0:
            return goal, touched, n_touched, heap, size


@numba.njit(cache=True)
def _candidate_pairs(
    traversable: BoolGrid, target_c: npt.NDArray[np.float64],
    offset_vox: npt.NDArray[np.float64], extra_c: npt.NDArray[np.float64],
    voxel_size: float, max_elevation_rad: float, max_range_m: float, eyes: BoolGrid,
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """The (eye, target) pairs whose eye voxel is inside the grid and traversable, and whose
    target is within the elevation and the range: (P,) the target of each (an index into
    `target_c`) and (P, 3) its eye voxel. Sets each eye voxel in `eyes`.

    Pairs come in `ViewpointCandidates.all`' order: each of `extra_c` with every target, then every
    target with every offset."""
    n_t, n_o, n_e = target_c.shape[0], offset_vox.shape[0], extra_c.shape[0]
    si, sj, sk = traversable.shape
    out_t = np.empty(n_e * n_t + n_t * n_o, dtype=np.int64)
    out_eye = np.empty((n_e * n_t + n_t * n_o, 3), dtype=np.int64)
    eye = np.empty(3, dtype=np.float64)
    n = 0
    for block in range(2):
        for a in range(n_e if block == 0 else n_t):
            for b in range(n_t if block == 0 else n_o):
                t = b if block == 0 else a
                if block == 0:
                    eye[0], eye[1], eye[2] = extra_c[a, 0], extra_c[a, 1], extra_c[a, 2]
                else:
                    eye[0] = target_c[t, 0] + offset_vox[b, 0]
                    eye[1] = target_c[t, 1] + offset_vox[b, 1]
                    eye[2] = target_c[t, 2] + offset_vox[b, 2]
                i, j, k = int(np.floor(eye[0])), int(np.floor(eye[1])), int(np.floor(eye[2]))
                if not (0 <= i < si and 0 <= j < sj and 0 <= k < sk) or not traversable[i, j, k]:
                    continue
                dx = (target_c[t, 0] - eye[0]) * voxel_size
                dy = (target_c[t, 1] - eye[1]) * voxel_size
                dz = (target_c[t, 2] - eye[2]) * voxel_size
                flat = dx * dx + dy * dy
                # Both tests must pass; the cheaper first.
                if np.sqrt(flat + dz * dz) > max_range_m:
                    continue
                if np.arctan2(abs(dz), np.sqrt(flat)) > max_elevation_rad:
                    continue
                out_t[n] = t
                out_eye[n, 0], out_eye[n, 1], out_eye[n, 2] = i, j, k
                eyes[i, j, k] = True
                n += 1
    return out_t[:n], out_eye[:n]


def _sampled(clusters: list[FrontierCluster], samples: int,
             excluded: BoolGrid | None) -> tuple[IndexArray, npt.NDArray[np.int64]]:
    """Up to `samples` voxels of each cluster (of those not `excluded`), evenly spaced in the
    cluster's order as `np.unique(np.linspace(0, n - 1, samples).astype(int))` picks them, and
    the cluster id of each."""
    none = np.zeros((0, 3), dtype=np.int64), np.zeros(0, dtype=np.int64)
    if not clusters:
        return none
    voxels = np.concatenate([c.indices for c in clusters])
    owner = np.repeat(np.arange(len(clusters)), [len(c.indices) for c in clusters])
    if excluded is not None:
        keep = ~excluded[voxels[:, 0], voxels[:, 1], voxels[:, 2]]
        voxels, owner = voxels[keep], owner[keep]
    if len(owner) == 0:
        return none
    # `owner` is sorted: each remaining cluster's first row and size (`np.unique`'s answer,
    # without its sort).
    first = np.flatnonzero(np.r_[True, owner[1:] != owner[:-1]])
    kept = owner[first]
    counts = np.diff(np.r_[first, len(owner)])
    # np.linspace(0, n - 1, samples) is i * ((n - 1) / (samples - 1)), the last exactly n - 1.
    if samples > 1:
        step = (counts - 1).astype(np.float64) / float(samples - 1)
        at = np.arange(samples, dtype=np.float64)[None, :] * step[:, None]
        at[:, -1] = counts - 1
    else:
        at = np.zeros((len(kept), 1))
    pick = at.astype(np.int64)
    # Each row is non-decreasing: `unique` keeps the first of each run.
    new = np.ones(pick.shape, dtype=np.bool_)
    new[:, 1:] = pick[:, 1:] != pick[:, :-1]
    ids = np.array([c.id for c in clusters], dtype=np.int64)[kept]
    return voxels[(first[:, None] + pick)[new]], np.broadcast_to(ids[:, None], pick.shape)[new]


def ring_offsets(distances_m: tuple[float, ...], heights_m: tuple[float, ...],
                 directions: int) -> npt.NDArray[np.float64]:
    """(D*H*N, 3) metre offsets on horizontal rings at each distance and height offset."""
    angles = np.arange(directions) * (2.0 * np.pi / directions)
    rows = [
        (d * np.cos(a), d * np.sin(a), h) for d in distances_m for h in heights_m for a in angles
    ]
    return np.array(rows, dtype=np.float64)


class ViewpointCandidates(CompiledAccept):
    """The candidate viewpoints of up to `samples_per_cluster` voxels of each cluster, with the
    costly test, the line of sight, run only where asked: for every candidate (`all`), or for
    the candidates at one eye voxel (`first_at`), as a search reaches them nearest first (as
    `DistanceField(accept=candidates)`, from the compiled search).

    Args:
        offsets_m: (R, 3) candidate offsets from a frontier voxel centre.
        excluded: frontier voxels to skip (e.g. targets given up on).
        extra: (E, 3) voxels tried as viewpoints of every sampled frontier voxel besides the
            ring (e.g. the vehicle's own, so that turning on the spot is an option).
        into_unknown: keep only viewpoints that also see into an unknown face neighbour of
            their frontier voxel (`sees_into_unknown`).

    Attributes:
        eyes: (nx, ny, nz) True on every voxel with a candidate before the line-of-sight test.
    """

    def __init__(
        self,
        view: MapView,
        clusters: list[FrontierCluster],
        offsets_m: npt.NDArray[np.float64],
        *,
        samples_per_cluster: int,
        max_elevation_rad: float,
        max_range_m: float,
        excluded: BoolGrid | None = None,
        extra: IndexArray | None = None,
        into_unknown: bool = False,
    ) -> None:
        self._view = view
        self._into_unknown = into_unknown
        self._target_idx, self._target_ids = _sampled(clusters, samples_per_cluster, excluded)
        # The (eye, frontier voxel) pairs, in voxel units with voxel centres at +0.5: each
        # `extra` voxel with every target, then every target with every ring offset. Only the
        # pairs whose eye is a traversable voxel are made; a whole-array pass over every pair
        # cost more than the rest of a Classic plan on the large areas.
        target_c: npt.NDArray[np.float64] = np.add(self._target_idx, 0.5, dtype=np.float64)
        extra_c = (np.asarray(extra, dtype=np.float64) + 0.5 if extra is not None and len(extra)
                   else np.zeros((0, 3), dtype=np.float64))
        self.eyes = np.zeros(view.shape, dtype=np.bool_)
        self._pair_t, self._voxels = _candidate_pairs(
            view.traversable, target_c, np.ascontiguousarray(offsets_m / view.voxel_size),
            extra_c, view.voxel_size, max_elevation_rad, max_range_m, self.eyes,
        )
        # Candidates grouped by eye voxel, each group in candidate order: the keys (eye voxel,
        # then candidate) are unique, so any sort gives that order.
        n = max(len(self._voxels), 1)
        flat = np.ravel_multi_index(tuple(self._voxels.T), view.shape)
        self._by_eye = np.sort(flat * n + np.arange(len(self._voxels)))
        # `first_at`'s answers, at each eye's first position in `_by_eye` (-2: not yet asked).
        self._first = np.full(len(self._voxels), -2, dtype=np.int64)

    def __len__(self) -> int:
        """Candidates before the line-of-sight test."""
        return len(self._voxels)

    def first_at(self, voxel: IndexArray) -> int:
        """The first candidate at eye `voxel` (3,) that passes the line-of-sight test, as an
        index into `all`'s order before filtering; -1 if none does."""
        flat = int(np.ravel_multi_index(tuple(voxel), self._view.shape))
        return int(_first_at(flat, self._view.state, self._into_unknown, self._voxels,
                             self._target_idx, self._pair_t, self._by_eye, self._first))

    def search_on(
        self, passable: BoolGrid, goals: BoolGrid, max_cost: float,
        dist: npt.NDArray[np.float64], parent: npt.NDArray[np.int64],
        done: npt.NDArray[np.bool_], touched: npt.NDArray[np.int64], n_touched: int,
        heap: HeapArray, size: int,
    ) -> tuple[int, npt.NDArray[np.int64], int, HeapArray, int]:
        """The search run on to the nearest eye voxel with a candidate in sight."""
        return _nearest_in_sight(
            passable, goals, max_cost, dist, parent, done, touched, n_touched, heap, size,
            self._view.state, self._into_unknown, self._voxels, self._target_idx, self._pair_t,
            self._by_eye, self._first)

    def accepts(self, voxel: IndexArray) -> bool:
        """Whether a candidate at eye `voxel` passes the line-of-sight test."""
        return self.first_at(voxel) >= 0

    def target_at(self, voxel: IndexArray) -> IndexArray:
        """(3,) the frontier voxel of the first candidate at `voxel` that passes the test."""
        row = self.first_at(voxel)
        if row < 0:
            raise ValueError(f"no viewpoint at {voxel.tolist()}")
        return self._target_idx[self._pair_t[row]]

    def all(self) -> Viewpoints:
        """Every candidate that passes the line-of-sight test, in order."""
        rows = np.arange(len(self._voxels))
        targets = self._target_idx[self._pair_t]
        eyes_c: npt.NDArray[np.float64] = np.add(self._voxels, 0.5, dtype=np.float64)
        if len(rows):
            aims: npt.NDArray[np.float64] = np.add(targets, 0.5, dtype=np.float64)
            rows = rows[_lines_clear_of(self._view.state, _OCCUPIED, eyes_c, aims)]
        if self._into_unknown and len(rows):
            rows = rows[sees_into_unknown(self._view, eyes_c[rows], targets[rows])]
        return Viewpoints(self._voxels[rows], targets[rows], self._target_ids[self._pair_t[rows]])


def sees_into_unknown(view: MapView, eyes: npt.NDArray[np.float64],
                      voxels: IndexArray) -> npt.NDArray[np.bool_]:
    """(N,) whether the line of sight from each eye ((N, 3), voxel units) to an unknown face
    neighbour of its frontier voxel ((N, 3)) crosses no occupied voxel, ends excluded.

    A frontier voxel no such line reaches cannot be cleared from that eye: the free voxels a
    floor slab's surface shares with grazing rays, say, lie over the slab's interior, unknown
    for good, that the occupied floor voxels around them hide."""
    return _sees_into_unknown(view.state, np.ascontiguousarray(eyes, dtype=np.float64),
                              np.ascontiguousarray(voxels, dtype=np.int64))
