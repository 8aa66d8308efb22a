"""Marching cubes of a TSDF voxel-block grid, compiled: the mesh of Open3D's
`VoxelBlockGrid.extract_triangle_mesh`, the same float32 vertices and the same triangles (each
with its winding), in an order fixed by the blocks' keys rather than by Open3D's threads.

Open3D's rules, which this module keeps:
- A cube is the eight voxels (x..x+1, y..y+1, z..z+1) of a voxel and its neighbours. It counts
  only when all eight are allocated and weighted above the threshold (float32 comparison); its
  case is the set of corners whose signed distance is below zero.
- An edge of a counted cube carries a vertex when its two ends' signs differ. Each vertex
  belongs to the voxel at the edge's low end, one per voxel and axis, however many cubes
  share the edge. It lies at `voxel_size * (i + ratio)` along the edge's axis, in float32,
  `ratio = (0 - t_o) / (t_e - t_o)`, `i` the voxel's global index; the other two
  coordinates are `voxel_size * (j + ratio * 0)` as Open3D computes them.
- A case's triangles are Open3D's own: `case_tables` reads them from Open3D's extraction of
  one small grid holding each of the 256 cases once, so the winding and the split of the
  ambiguous cases are whatever the installed Open3D does.

The scratch is 3 bytes per voxel of the allocated blocks (the cube's case, then each voxel's
edge bits and its vertices' rank within its block); Open3D's own extraction holds 16 bytes per
voxel for the whole call. `tests/sim/test_tsdf_mesh.py` compares the two meshes.
"""

from __future__ import annotations

import functools
from typing import Any

import numba
import numpy as np
import numpy.typing as npt

from sim.open3d_any import o3c
from sim.tsdf_blocks import block_arrays, block_grid, upper_neighbours

__all__ = ["EDGE_SHIFTS", "MAX_RESOLUTION", "case_tables", "marching_cubes", "open3d_mesh",
           "same_mesh"]

Vertices = npt.NDArray[np.float64]
Triangles = npt.NDArray[np.int32]
Int64s = npt.NDArray[np.int64]


def _edge_shifts() -> Int64s:
    """(12, 4): for each edge of a cube, its low end's offset from the cube's base voxel
    (dx, dy, dz) and its axis. Edge `4 * axis + a + 2 * b` runs along `axis` from the corner
    whose other two coordinates, in x, y, z order, are a and b."""
    shifts = np.zeros((12, 4), dtype=np.int64)
    for axis in range(3):
        others = [k for k in range(3) if k != axis]
        for a in range(2):
            for b in range(2):
                row = shifts[4 * axis + a + 2 * b]
                row[others[0]], row[others[1]], row[3] = a, b, axis
    return shifts


EDGE_SHIFTS = _edge_shifts()
# A voxel's code holds its block's vertex count before it above three edge bits, in 16 bits.
MAX_RESOLUTION = 13
# Corner i of a cube is its voxel (i & 1, (i >> 1) & 1, (i >> 2) & 1) from the base voxel; a
# case sets bit i when that corner's signed distance is below zero.
_CORNERS = np.array([(i & 1, (i >> 1) & 1, (i >> 2) & 1) for i in range(8)], dtype=np.int64)


def _sign_change_edges(case: int) -> int:
    """Bit mask of the edges whose two ends' signs differ in `case`."""
    below = {tuple(_CORNERS[i]) for i in range(8) if case >> i & 1}
    mask = 0
    for edge, (dx, dy, dz, axis) in enumerate(EDGE_SHIFTS.tolist()):
        end = [dx, dy, dz]
        end[axis] += 1
        if ((dx, dy, dz) in below) != (tuple(end) in below):
            mask |= 1 << edge
    return mask


@functools.cache
def case_tables() -> tuple[Int64s, Int64s]:
    """(256,) each case's edges carrying a vertex (a bit mask over `EDGE_SHIFTS`) and
    (256, 16) its triangles, three edges each as Open3D orders a triangle's corners, -1 after
    the last: read from Open3D's marching cubes of a grid holding each case once, in a cube
    of its own with unweighted voxels around it (so that no other cube counts)."""
    res, spacing = 8, 3
    keys = np.array([(x, y, 0) for x in range(6) for y in range(6)], dtype=np.int32)
    grid = block_grid(1.0, res, len(keys))
    buf, _ = grid.hashmap().activate(o3c.Tensor(keys))
    slot = dict(zip(map(tuple, keys.tolist()), buf.numpy().tolist(), strict=True))
    tsdf, weight = grid.attribute("tsdf").numpy(), grid.attribute("weight").numpy()
    tsdf[...], weight[...] = 0.0, 0.0
    for case in range(256):
        base = np.array([spacing * (case % 16), spacing * (case // 16), 0])
        for i, corner in enumerate(_CORNERS):
            x, y, z = base + corner
            s = slot[(x // res, y // res, 0)]
            tsdf[s, z, y % res, x % res, 0] = -0.5 if case >> i & 1 else 0.5
            weight[s, z, y % res, x % res, 0] = 2.0
    positions, triangles = open3d_mesh(grid, 1.0)
    # With voxels of 1 m and signed distances of +-0.5, a vertex lies at the middle of its edge.
    low = np.floor(positions).astype(np.int64)
    axis = np.argmax(positions - low, axis=1)
    cube = spacing * (low // spacing)
    offset = low - cube
    others = np.array([[1, 2], [0, 2], [0, 1]])[axis]
    edge = 4 * axis + np.take_along_axis(offset, others, 1) @ np.array([1, 2])
    case_of = cube[:, 0] // spacing + 16 * (cube[:, 1] // spacing)
    edges = np.zeros(256, dtype=np.int64)
    np.bitwise_or.at(edges, case_of, np.left_shift(1, edge))
    expected = np.array([_sign_change_edges(c) for c in range(256)], dtype=np.int64)
    if not np.array_equal(edges, expected):
        raise RuntimeError("Open3D's marching cubes placed vertices on edges without a sign "
                           "change; its rules have changed")
    table = np.full((256, 16), -1, dtype=np.int64)
    filled = np.zeros(256, dtype=np.int64)
    for corners in triangles:  # Open3D writes a cube's triangles in its case's order
        case = int(case_of[corners[0]])
        table[case, filled[case]:filled[case] + 3] = edge[corners]
        filled[case] += 3
    return edges, table


def marching_cubes(grid: Any, voxel_size: float,
                   weight_threshold: float) -> tuple[Vertices, Triangles]:
    """The marching-cubes mesh of `grid` (an Open3D CPU `VoxelBlockGrid` with float32 "tsdf"
    and "weight" attributes, voxels of `voxel_size` metres): (V, 3) vertices (float32
    positions, as float64), blocks in key order, then voxels (z, y, x), then axes; and (F, 3)
    int32 triangles, block by block and voxel by voxel."""
    blocks = block_arrays(grid)
    if blocks is None:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int32)
    edges, table = case_tables()
    after = upper_neighbours(blocks)
    res = blocks.tsdf.shape[1]
    if res > MAX_RESOLUTION:
        raise ValueError(f"marching cubes takes blocks of at most {MAX_RESOLUTION}³ voxels, "
                         f"not {res}³")
    cases = np.zeros((len(blocks.order), res, res, res), dtype=np.uint8)
    codes = np.zeros((len(blocks.order), res, res, res), dtype=np.uint16)
    n_triangles = _mark(blocks.order, after, blocks.tsdf, blocks.weight,
                        np.float32(weight_threshold), edges, (table >= 0).sum(axis=1) // 3,
                        EDGE_SHIFTS, cases, codes)
    starts = _rank(codes)
    vertices = np.empty((int(starts[-1]), 3), dtype=np.float64)
    _place(blocks.keys, blocks.order, after, blocks.tsdf, codes, starts,
           np.float32(voxel_size), vertices)
    triangles = np.empty((n_triangles, 3), dtype=np.int32)
    _connect(after, cases, codes, starts, table, EDGE_SHIFTS, triangles)
    return vertices, triangles


def open3d_mesh(grid: Any, weight_threshold: float) -> tuple[npt.NDArray[np.float32],
                                                             Triangles]:
    """Open3D's own extraction of `grid`: (V, 3) float32 vertices and (F, 3) int32 triangles
    (the reference `marching_cubes` reproduces)."""
    try:
        mesh = grid.extract_triangle_mesh(weight_threshold)
    except RuntimeError:  # Open3D raises instead of returning an empty mesh
        mesh = None
    if mesh is None or "positions" not in mesh.vertex or "indices" not in mesh.triangle:
        return np.zeros((0, 3), dtype=np.float32), np.zeros((0, 3), dtype=np.int32)
    return (mesh.vertex.positions.numpy().copy(),
            mesh.triangle.indices.numpy().astype(np.int32))


MeshLike = tuple[npt.ArrayLike, npt.ArrayLike]


def same_mesh(a: MeshLike, b: MeshLike) -> bool:
    """Whether meshes `a` and `b` ((V, 3) vertices, (F, 3) triangles) have the same vertices as
    float32 positions, to the bit, and the same triangles, each as its three corners' positions
    with its winding, in any order."""
    (va, ta), (vb, tb) = ((np.asarray(v, dtype=np.float32), np.asarray(t, dtype=np.int64))
                          for v, t in (a, b))
    if va.shape != vb.shape or ta.shape != tb.shape:
        return False
    return (np.array_equal(_sorted_rows(va.view(np.uint32)), _sorted_rows(vb.view(np.uint32)))
            and np.array_equal(_triangle_rows(va, ta), _triangle_rows(vb, tb)))


def _sorted_rows(rows: npt.NDArray[Any]) -> npt.NDArray[Any]:
    return rows[np.lexsort(rows.T[::-1])] if len(rows) else rows


def _triangle_rows(vertices: npt.NDArray[np.float32], triangles: Int64s) -> Int64s:
    """Each triangle as its corners' 9 coordinate bits, turned (the winding kept) to the least
    of its three turns, the rows sorted."""
    corners = vertices.view(np.uint32).astype(np.int64)[triangles]  # (F, 3, 3)
    rows = np.arange(len(triangles))
    least = corners.reshape(-1, 9)
    for turn in (1, 2):
        other = np.roll(corners, -turn, axis=1).reshape(-1, 9)
        differ = other != least
        first = np.argmax(differ, axis=1)
        less = differ.any(axis=1) & (other[rows, first] < least[rows, first])
        least = np.where(less[:, None], other, least)
    return _sorted_rows(least)


@numba.njit(cache=True)
def _corner(after: Int64s, p: int, x: int, y: int, z: int,
            res: int) -> tuple[int, int, int, int]:  # pragma: no cover - numba
    """The block position and local voxel of voxel (x, y, z) of block `p`, each coordinate
    at most one past the block (position -1 where that block is not allocated)."""
    k = 0
    if x == res:
        x, k = 0, k | 1
    if y == res:
        y, k = 0, k | 2
    if z == res:
        z, k = 0, k | 4
    return after[p, k], x, y, z


@numba.njit(cache=True)
def _mark(order: Int64s, after: Int64s, tsdf: npt.NDArray[np.float32],
          weight: npt.NDArray[np.float32], limit: np.float32, edges: Int64s,
          triangle_counts: Int64s, shifts: Int64s, cases: npt.NDArray[np.uint8],
          codes: npt.NDArray[np.uint16]) -> int:  # pragma: no cover - numba
    """Writes each counted cube's case to `cases` (0 for none) and sets, in `codes`, bit `axis`
    of the voxel owning each edge that carries a vertex; returns the number of triangles."""
    res = tsdf.shape[1]
    zero = np.float32(0.0)
    n_triangles = 0
    for p in range(order.shape[0]):
        s = order[p]
        for z in range(res):
            for y in range(res):
                for x in range(res):
                    if weight[s, z, y, x] <= limit:
                        continue
                    case = 0
                    counted = True
                    for i in range(8):
                        q, cx, cy, cz = _corner(after, p, x + (i & 1), y + (i >> 1 & 1),
                                                z + (i >> 2 & 1), res)
                        if q < 0:
                            counted = False
                            break
                        sq = order[q]
                        if weight[sq, cz, cy, cx] <= limit:
                            counted = False
                            break
                        if tsdf[sq, cz, cy, cx] < zero:
                            case |= 1 << i
                    if not counted or case == 0 or case == 255:
                        continue
                    cases[p, z, y, x] = case
                    mask = edges[case]
                    for e in range(12):
                        if mask >> e & 1:
                            q, ox, oy, oz = _corner(after, p, x + shifts[e, 0],
                                                    y + shifts[e, 1], z + shifts[e, 2], res)
                            codes[q, oz, oy, ox] |= np.uint16(1 << shifts[e, 3])
                    n_triangles += triangle_counts[case]
    return n_triangles


@numba.njit(cache=True)
def _rank(codes: npt.NDArray[np.uint16]) -> Int64s:  # pragma: no cover - numba
    """Adds to each voxel's code, above its three edge bits, the number of vertices of its
    block before its own (at most 3 R³: `MAX_RESOLUTION`); returns (B + 1,) the first vertex
    of each block and the total."""
    res = codes.shape[1]
    starts = np.zeros(codes.shape[0] + 1, dtype=np.int64)
    total = 0
    for p in range(codes.shape[0]):
        starts[p] = total
        before = 0
        for z in range(res):
            for y in range(res):
                for x in range(res):
                    c = codes[p, z, y, x]
                    codes[p, z, y, x] = c | np.uint16(before << 3)
                    before += (c & 1) + (c >> 1 & 1) + (c >> 2 & 1)
        total += before
    starts[codes.shape[0]] = total
    return starts


@numba.njit(cache=True)
def _place(keys: npt.NDArray[np.int32], order: Int64s, after: Int64s,
           tsdf: npt.NDArray[np.float32], codes: npt.NDArray[np.uint16], starts: Int64s,
           voxel: np.float32, out: Vertices) -> None:  # pragma: no cover - numba
    """Writes each vertex where Open3D puts it (float32 arithmetic, module docstring)."""
    res = tsdf.shape[1]
    zero, one = np.float32(0.0), np.float32(1.0)
    for p in range(order.shape[0]):
        s = order[p]
        for z in range(res):
            for y in range(res):
                for x in range(res):
                    c = codes[p, z, y, x]
                    if (c & 7) == 0:
                        continue
                    n = starts[p] + (c >> 3)
                    t_o = tsdf[s, z, y, x]
                    gx = np.float32(keys[s, 0] * res + x)
                    gy = np.float32(keys[s, 1] * res + y)
                    gz = np.float32(keys[s, 2] * res + z)
                    for a in range(3):
                        if not c >> a & 1:
                            continue
                        q, ex, ey, ez = _corner(after, p, x + (a == 0), y + (a == 1),
                                                z + (a == 2), res)
                        t_e = tsdf[order[q], ez, ey, ex]
                        ratio = (zero - t_o) / (t_e - t_o)
                        out[n, 0] = voxel * (gx + ratio * (one if a == 0 else zero))
                        out[n, 1] = voxel * (gy + ratio * (one if a == 1 else zero))
                        out[n, 2] = voxel * (gz + ratio * (one if a == 2 else zero))
                        n += 1


@numba.njit(cache=True)
def _connect(after: Int64s, cases: npt.NDArray[np.uint8], codes: npt.NDArray[np.uint16],
             starts: Int64s, table: Int64s, shifts: Int64s,
             out: Triangles) -> None:  # pragma: no cover - numba
    """Writes each counted cube's triangles, its case's edges turned into vertex indices."""
    res = cases.shape[1]
    n = 0
    for p in range(cases.shape[0]):
        for z in range(res):
            for y in range(res):
                for x in range(res):
                    case = cases[p, z, y, x]
                    if case == 0:
                        continue
                    t = 0
                    while t < 16 and table[case, t] >= 0:
                        for k in range(3):
                            e = table[case, t + k]
                            q, ox, oy, oz = _corner(after, p, x + shifts[e, 0],
                                                    y + shifts[e, 1], z + shifts[e, 2], res)
                            c = codes[q, oz, oy, ox]
                            below = c & ((1 << shifts[e, 3]) - 1)
                            out[n, k] = starts[q] + (c >> 3) + (below & 1) + (below >> 1 & 1)
                        n += 1
                        t += 3
