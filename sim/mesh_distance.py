"""Exact distance from points to a triangle mesh, in float64.

The surface measures score every vertex of the reconstructed mesh by its distance to the
area's mesh (millions of vertices on the large areas). Open3D's `RaycastingScene.compute_distance`
works in float32 and, near long thin triangles (pipes, rails), returns the distance to a farther
triangle: on a FACILITY C reconstruction, 2 % of the vertices came out up to 7 mm too far.
Here every distance is the least over the triangles that can be within reach, each computed
exactly (Ericson, *Real-Time Collision Detection*, 5.1.5), in passes of growing reach.
"""

from __future__ import annotations

import numba
import numpy as np
import numpy.typing as npt

from sim.cell_lists import cell_edge, cell_lists

# Reach of the first pass, metres: the reconstructed surface lies within a few TSDF voxels of
# the true one, so nearly every point is settled by it; the rest go again with twice the reach.
FIRST_REACH_M = 0.15


def distance_to_mesh(vertices: npt.ArrayLike, triangles: npt.ArrayLike,
                     points: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """(N,) distances in metres from `points` (N, 3) to the mesh `vertices` (V, 3), `triangles`
    (T, 3) vertex indices; infinite when the mesh has no triangle."""
    verts = np.ascontiguousarray(vertices, dtype=np.float64).reshape(-1, 3)
    tris = np.ascontiguousarray(triangles, dtype=np.int64).reshape(-1, 3)
    query = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    best = np.full(len(query), np.inf)
    if len(tris) == 0 or len(query) == 0:
        return best
    low, high = verts.min(axis=0), verts.max(axis=0)
    reach = cell_edge(low, high, FIRST_REACH_M, 2)
    # int32 indices: half the memory beside the mesh's millions of vertices.
    pending: npt.NDArray[np.integer] = np.arange(
        len(query), dtype=np.int32 if len(query) < 2**31 else np.int64)
    while len(pending):
        lists = cell_lists(query, pending, low, high, reach, 2)
        _nearer_within(verts, tris, lists.origin, reach, lists.shape, lists.start,
                       lists.members, query, best)
        # A point whose least distance found is within the reach has its exact distance: every
        # triangle that close was tried. Once the reach spans the mesh and the points, all have.
        # (Compiled: the pending points' box and those still farther than the reach without
        # copying millions of them, at the run's memory peak.)
        box_low, box_high = low.copy(), high.copy()
        _grow_box(query, pending, box_low, box_high)
        if reach >= float(np.linalg.norm(box_high - box_low)):
            break
        pending = _farther_than(best, pending, reach * reach)
        reach *= 2.0
    return np.sqrt(best, out=best)


@numba.njit(cache=True)
def _grow_box(query: npt.NDArray[np.float64], which: npt.NDArray[np.integer],
              low: npt.NDArray[np.float64], high: npt.NDArray[np.float64],
              ) -> None:  # pragma: no cover - numba
    """Grows the box low..high to hold `query[which]`."""
    for n in range(which.shape[0]):
        for ax in range(3):
            v = query[which[n], ax]
            low[ax] = min(low[ax], v)
            high[ax] = max(high[ax], v)


@numba.njit(cache=True)
def _farther_than(best: npt.NDArray[np.float64], which: npt.NDArray[np.integer],
                  limit: float) -> npt.NDArray[np.integer]:  # pragma: no cover - numba
    """The entries of `which` whose `best` exceeds `limit`, in order."""
    kept = 0
    for n in range(which.shape[0]):
        kept += best[which[n]] > limit
    out = np.empty(kept, dtype=which.dtype)
    kept = 0
    for n in range(which.shape[0]):
        if best[which[n]] > limit:
            out[kept] = which[n]
            kept += 1
    return out


@numba.njit(cache=True)
def _nearer_within(verts: npt.NDArray[np.float64], tris: npt.NDArray[np.int64],
                   origin: npt.NDArray[np.float64], reach: float,
                   shape: npt.NDArray[np.int64], start: npt.NDArray[np.integer],
                   members: npt.NDArray[np.integer], query: npt.NDArray[np.float64],
                   best: npt.NDArray[np.float64]) -> None:  # pragma: no cover - numba
    """Lowers `best` (squared distances) with every triangle within `reach` of a point: each
    triangle visits the points in the cells its bounding box, grown by the reach, overlaps
    (`members[start[c]:start[c + 1]]` in cell c of a grid of `shape` cells of edge `reach`)."""
    reach2 = reach * reach
    lo = np.empty(3, np.int64)
    hi = np.empty(3, np.int64)
    box = np.empty(6)
    for t in range(tris.shape[0]):
        a, b, c = tris[t, 0], tris[t, 1], tris[t, 2]
        empty = False
        for ax in range(3):
            box[ax] = min(verts[a, ax], verts[b, ax], verts[c, ax])
            box[ax + 3] = max(verts[a, ax], verts[b, ax], verts[c, ax])
            lo[ax] = max(int(np.floor((box[ax] - reach - origin[ax]) / reach)), 0)
            hi[ax] = min(int(np.floor((box[ax + 3] + reach - origin[ax]) / reach)),
                         shape[ax] - 1)
            empty = empty or hi[ax] < lo[ax]
        if empty:
            continue
        abx, aby, abz = verts[b, 0] - verts[a, 0], verts[b, 1] - verts[a, 1], \
            verts[b, 2] - verts[a, 2]
        acx, acy, acz = verts[c, 0] - verts[a, 0], verts[c, 1] - verts[a, 1], \
            verts[c, 2] - verts[a, 2]
        # No area (a repeated vertex, or all three on a line): the distance to its edges.
        flat = _sq(aby * acz - abz * acy, abz * acx - abx * acz, abx * acy - aby * acx) == 0.0
        for i in range(lo[0], hi[0] + 1):
            for j in range(lo[1], hi[1] + 1):
                row = (i * shape[1] + j) * shape[2]
                for k in range(lo[2], hi[2] + 1):
                    for s in range(start[row + k], start[row + k + 1]):
                        q = members[s]
                        px, py, pz = query[q, 0], query[q, 1], query[q, 2]
                        # The box's distance bounds the triangle's: skip what cannot be nearer.
                        ex = max(box[0] - px, 0.0, px - box[3])
                        ey = max(box[1] - py, 0.0, py - box[4])
                        ez = max(box[2] - pz, 0.0, pz - box[5])
                        if ex * ex + ey * ey + ez * ez >= min(best[q], reach2):
                            continue
                        apx, apy, apz = px - verts[a, 0], py - verts[a, 1], pz - verts[a, 2]
                        if flat:
                            d = min(_segment_sq(apx, apy, apz, abx, aby, abz),
                                    _segment_sq(apx, apy, apz, acx, acy, acz),
                                    _segment_sq(apx - abx, apy - aby, apz - abz,
                                                acx - abx, acy - aby, acz - abz))
                        else:
                            d = _point_triangle_sq(apx, apy, apz, abx, aby, abz, acx, acy, acz)
                        if d < best[q]:
                            best[q] = d


@numba.njit(cache=True)
def _point_triangle_sq(apx: float, apy: float, apz: float, abx: float, aby: float, abz: float,
                       acx: float, acy: float,
                       acz: float) -> float:  # pragma: no cover - numba
    """Squared distance from point p to triangle abc (of non-zero area), given ap, ab and ac,
    by the Voronoi region of the triangle that holds p's projection (vertex, edge or face)."""
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return _sq(apx, apy, apz)
    bpx, bpy, bpz = apx - abx, apy - aby, apz - abz
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return _sq(bpx, bpy, bpz)
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return _sq(apx - v * abx, apy - v * aby, apz - v * abz)
    cpx, cpy, cpz = apx - acx, apy - acy, apz - acz
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:
        return _sq(cpx, cpy, cpz)
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return _sq(apx - w * acx, apy - w * acy, apz - w * acz)
    bcx, bcy, bcz = acx - abx, acy - aby, acz - abz
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and d4 - d3 >= 0.0 and d5 - d6 >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return _sq(bpx - w * bcx, bpy - w * bcy, bpz - w * bcz)
    total = va + vb + vc
    v = vb / total
    w = vc / total
    return _sq(apx - abx * v - acx * w, apy - aby * v - acy * w, apz - abz * v - acz * w)


@numba.njit(cache=True)
def _segment_sq(px: float, py: float, pz: float, dx: float, dy: float,
                dz: float) -> float:  # pragma: no cover - numba
    """Squared distance from p (relative to the segment's start) to the segment d."""
    length2 = dx * dx + dy * dy + dz * dz
    s = 0.0 if length2 <= 0.0 else min(max((px * dx + py * dy + pz * dz) / length2, 0.0), 1.0)
    return _sq(px - s * dx, py - s * dy, pz - s * dz)


@numba.njit(cache=True)
def _sq(x: float, y: float, z: float) -> float:  # pragma: no cover - numba
    return x * x + y * y + z * z
