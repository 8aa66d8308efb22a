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

from planners.search import BoolGrid, IndexArray
from sim.map_view import FrontierCluster, MapView
from sim.occupancy import VoxelState

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
def _line_clear(blocked: BoolGrid, a: npt.NDArray[np.float64],
                b: npt.NDArray[np.float64]) -> bool:
    """Whether no voxel strictly between the end voxels of a→b (voxel units) is blocked."""
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
        if blocked[i, j, k]:
            return False
    return True


@numba.njit(cache=True)
def lines_clear(
    blocked: BoolGrid, a: npt.NDArray[np.float64], b: npt.NDArray[np.float64]
) -> npt.NDArray[np.bool_]:
    """For each pair a[i]→b[i] (voxel units), whether no voxel strictly between the two end
    voxels is blocked."""
    out = np.ones(a.shape[0], dtype=np.bool_)
    for r in range(a.shape[0]):
        out[r] = _line_clear(blocked, a[r], b[r])
    return out


@numba.njit(cache=True)
def _sees_into_unknown(occupied: BoolGrid, state: npt.NDArray[np.uint8], unknown: int,
                       eyes: npt.NDArray[np.float64],
                       voxels: npt.NDArray[np.int64]) -> npt.NDArray[np.bool_]:
    si, sj, sk = state.shape
    seen = np.zeros(voxels.shape[0], dtype=np.bool_)
    end = np.empty(3, dtype=np.float64)
    for r in range(voxels.shape[0]):
        for f in range(FACES.shape[0]):
            i = voxels[r, 0] + FACES[f, 0]
            j = voxels[r, 1] + FACES[f, 1]
            k = voxels[r, 2] + FACES[f, 2]
            if not (0 <= i < si and 0 <= j < sj and 0 <= k < sk) or state[i, j, k] != unknown:
                continue
            end[0], end[1], end[2] = i + 0.5, j + 0.5, k + 0.5
            if _line_clear(occupied, eyes[r], end):
                seen[r] = True
                break
    return seen


@numba.njit(cache=True)
def _traversable_pairs(
    traversable: BoolGrid, target_c: npt.NDArray[np.float64],
    offset_vox: npt.NDArray[np.float64], extra_c: npt.NDArray[np.float64],
) -> npt.NDArray[np.int64]:
    """Indices of the (eye, target) pairs whose eye voxel is inside the grid and traversable.

    Pairs are numbered as `frontier_viewpoints` orders them: `extra_c[e]` with `target_c[t]` is
    pair e * T + t; `target_c[t] + offset_vox[o]` with `target_c[t]` is E * T + t * O + o."""
    n_t, n_o, n_e = target_c.shape[0], offset_vox.shape[0], extra_c.shape[0]
    si, sj, sk = traversable.shape
    out = np.empty(n_e * n_t + n_t * n_o, dtype=np.int64)
    n = 0
    for e in range(n_e):
        i = int(np.floor(extra_c[e, 0]))
        j = int(np.floor(extra_c[e, 1]))
        k = int(np.floor(extra_c[e, 2]))
        if 0 <= i < si and 0 <= j < sj and 0 <= k < sk and traversable[i, j, k]:
            for t in range(n_t):
                out[n] = e * n_t + t
                n += 1
    base = n_e * n_t
    for t in range(n_t):
        for o in range(n_o):
            i = int(np.floor(target_c[t, 0] + offset_vox[o, 0]))
            j = int(np.floor(target_c[t, 1] + offset_vox[o, 1]))
            k = int(np.floor(target_c[t, 2] + offset_vox[o, 2]))
            if 0 <= i < si and 0 <= j < sj and 0 <= k < sk and traversable[i, j, k]:
                out[n] = base + t * n_o + o
                n += 1
    return out[:n]


def ring_offsets(distances_m: tuple[float, ...], heights_m: tuple[float, ...],
                 directions: int) -> npt.NDArray[np.float64]:
    """(D*H*N, 3) metre offsets on horizontal rings at each distance and height offset."""
    angles = np.arange(directions) * (2.0 * np.pi / directions)
    rows = [
        (d * np.cos(a), d * np.sin(a), h) for d in distances_m for h in heights_m for a in angles
    ]
    return np.array(rows, dtype=np.float64)


def frontier_viewpoints(
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
) -> Viewpoints:
    """Viewpoints for up to `samples_per_cluster` voxels of each cluster.

    Args:
        offsets_m: (R, 3) candidate offsets from a frontier voxel centre.
        excluded: frontier voxels to skip (e.g. targets given up on).
        extra: (E, 3) voxels tried as viewpoints of every sampled frontier voxel besides the
            ring (e.g. the vehicle's own, so that turning on the spot is an option).
        into_unknown: keep only viewpoints that also see into an unknown face neighbour of
            their frontier voxel (`sees_into_unknown`).
    """
    targets, ids = [], []
    for cluster in clusters:
        idx = cluster.indices
        if excluded is not None:
            idx = idx[~excluded[idx[:, 0], idx[:, 1], idx[:, 2]]]
        if len(idx) == 0:
            continue
        pick = np.unique(np.linspace(0, len(idx) - 1, samples_per_cluster).astype(np.int64))
        targets.append(idx[pick])
        ids.append(np.full(len(pick), cluster.id, dtype=np.int64))
    empty = np.zeros((0, 3), dtype=np.int64)
    if not targets:
        return Viewpoints(empty, empty, np.zeros(0, dtype=np.int64))
    target_idx = np.concatenate(targets)
    target_ids = np.concatenate(ids)
    vs = view.voxel_size
    offset_vox = offsets_m / vs
    # The (eye, frontier voxel) pairs, in voxel units with voxel centres at +0.5: each `extra`
    # voxel with every target, then every target with every ring offset. Only the pairs whose
    # eye is a traversable voxel are made; a whole-array pass over every pair cost more than
    # the rest of a Classic plan on the large areas.
    target_c = target_idx.astype(np.float64) + 0.5
    extra_c = (np.asarray(extra, dtype=np.float64) + 0.5 if extra is not None and len(extra)
               else np.zeros((0, 3), dtype=np.float64))
    kept = _traversable_pairs(view.traversable, target_c, offset_vox, extra_c)
    n_extra = len(extra_c) * len(target_c)
    from_extra = kept < n_extra
    ring = kept[~from_extra] - n_extra
    pair_t = np.concatenate([kept[from_extra] % len(target_c), ring // len(offset_vox)])
    cand_c = np.concatenate([extra_c[kept[from_extra] // len(target_c)],
                             target_c[ring // len(offset_vox)]
                             + offset_vox[ring % len(offset_vox)]])
    cand = np.floor(cand_c).astype(np.int64)
    tgt_c = target_c[pair_t]
    rep_targets = target_idx[pair_t]
    rep_ids = target_ids[pair_t]
    delta = (tgt_c - cand_c) * vs
    horizontal = np.linalg.norm(delta[:, :2], axis=1)
    ok = np.arctan2(np.abs(delta[:, 2]), horizontal) <= max_elevation_rad
    ok &= np.linalg.norm(delta, axis=1) <= max_range_m
    cand, cand_c, tgt_c, rep_targets, rep_ids = (
        cand[ok], cand_c[ok], tgt_c[ok], rep_targets[ok], rep_ids[ok]
    )
    if len(cand):
        clear = lines_clear(view.occupied, np.floor(cand_c) + 0.5, tgt_c)
        cand, rep_targets, rep_ids = cand[clear], rep_targets[clear], rep_ids[clear]
    if into_unknown and len(cand):
        into = sees_into_unknown(view, cand.astype(np.float64) + 0.5, rep_targets)
        cand, rep_targets, rep_ids = cand[into], rep_targets[into], rep_ids[into]
    return Viewpoints(cand, rep_targets, rep_ids)


def sees_into_unknown(view: MapView, eyes: npt.NDArray[np.float64],
                      voxels: IndexArray) -> npt.NDArray[np.bool_]:
    """(N,) whether the line of sight from each eye ((N, 3), voxel units) to an unknown face
    neighbour of its frontier voxel ((N, 3)) crosses no occupied voxel, ends excluded.

    A frontier voxel no such line reaches cannot be cleared from that eye: the free voxels a
    floor slab's surface shares with grazing rays, say, lie over the slab's interior, unknown
    for good, that the occupied floor voxels around them hide."""
    return _sees_into_unknown(view.occupied, view.state, int(VoxelState.UNKNOWN),
                              np.ascontiguousarray(eyes, dtype=np.float64),
                              np.ascontiguousarray(voxels, dtype=np.int64))
