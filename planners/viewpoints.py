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
def lines_clear(
    blocked: BoolGrid, a: npt.NDArray[np.float64], b: npt.NDArray[np.float64]
) -> npt.NDArray[np.bool_]:
    """For each pair a[i]→b[i] (voxel units), whether no voxel strictly between the two end
    voxels is blocked."""
    out = np.ones(a.shape[0], dtype=np.bool_)
    for r in range(a.shape[0]):
        ai, aj, ak = int(np.floor(a[r, 0])), int(np.floor(a[r, 1])), int(np.floor(a[r, 2]))
        bi, bj, bk = int(np.floor(b[r, 0])), int(np.floor(b[r, 1])), int(np.floor(b[r, 2]))
        length = np.sqrt(np.sum((b[r] - a[r]) ** 2))
        steps = max(1, int(np.ceil(length * 4.0)))
        for s in range(1, steps):
            t = s / steps
            i = int(np.floor(a[r, 0] + (b[r, 0] - a[r, 0]) * t))
            j = int(np.floor(a[r, 1] + (b[r, 1] - a[r, 1]) * t))
            k = int(np.floor(a[r, 2] + (b[r, 2] - a[r, 2]) * t))
            if (i == ai and j == aj and k == ak) or (i == bi and j == bj and k == bk):
                continue
            if blocked[i, j, k]:
                out[r] = False
                break
    return out


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
    # Every (target, offset) pair, in voxel units with voxel centres at +0.5.
    target_c = target_idx.astype(np.float64) + 0.5
    cand_c = (target_c[:, None, :] + offset_vox[None, :, :]).reshape(-1, 3)
    tgt_c = np.repeat(target_c, len(offset_vox), axis=0)
    rep_targets = np.repeat(target_idx, len(offset_vox), axis=0)
    rep_ids = np.repeat(target_ids, len(offset_vox))
    if extra is not None and len(extra):
        extra_c = np.asarray(extra, dtype=np.float64) + 0.5
        cand_c = np.vstack([np.repeat(extra_c, len(target_c), axis=0), cand_c])
        tgt_c = np.vstack([np.tile(target_c, (len(extra_c), 1)), tgt_c])
        rep_targets = np.vstack([np.tile(target_idx, (len(extra_c), 1)), rep_targets])
        rep_ids = np.concatenate([np.tile(target_ids, len(extra_c)), rep_ids])
    cand = np.floor(cand_c).astype(np.int64)
    shape = np.array(view.shape)
    ok = np.all((cand >= 0) & (cand < shape), axis=1)
    cand, cand_c, tgt_c, rep_targets, rep_ids = (
        cand[ok], cand_c[ok], tgt_c[ok], rep_targets[ok], rep_ids[ok]
    )
    ok = view.traversable[cand[:, 0], cand[:, 1], cand[:, 2]]
    delta = (tgt_c - cand_c) * vs
    horizontal = np.linalg.norm(delta[:, :2], axis=1)
    ok &= np.arctan2(np.abs(delta[:, 2]), horizontal) <= max_elevation_rad
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
    shape = np.array(view.shape)
    seen = np.zeros(len(voxels), dtype=np.bool_)
    for face in FACES:
        nb = voxels + face
        inside = np.all((nb >= 0) & (nb < shape), axis=1)
        nb = np.where(inside[:, None], nb, 0)
        unknown = inside & (view.state[nb[:, 0], nb[:, 1], nb[:, 2]] == VoxelState.UNKNOWN)
        todo = np.flatnonzero(unknown & ~seen)
        if len(todo):
            seen[todo] = lines_clear(view.occupied, np.ascontiguousarray(eyes[todo]),
                                     nb[todo].astype(np.float64) + 0.5)
    return seen
