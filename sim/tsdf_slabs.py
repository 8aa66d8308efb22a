"""Marching cubes of a TSDF voxel-block grid, one slab of blocks at a time.

Open3D's `VoxelBlockGrid.extract_triangle_mesh` allocates a scratch table of 16 bytes per voxel
of every allocated block (8 KiB per 8³ block) for the whole call, and a triangle buffer of
72 bytes per vertex; on a large area that is 400-600 MiB above the run's resident set, at the
very end of the run. Here the grid is cut along x into slabs of at most `SLAB_BLOCKS` blocks,
and each slab is meshed in a grid of its own holding the slab plus the first voxel plane of
the next slab (the cubes on the slab's far face need it). Every voxel of that extra layer but
its first plane gets weight 0, which Open3D's marching cubes skips, so a slab yields exactly
the triangles of the cubes whose base voxel lies in it.

A vertex sits on one voxel edge; the vertices on a plane between two slabs that belong to the
edges of that plane's voxels are made by both slabs, and are merged: a vertex of the upper slab
on the plane is replaced by an equal vertex of the lower slab, one for one. So the mesh has the
same vertices and triangles (as float32 positions, winding kept) as one extraction of the whole
grid, in another order. Pairing by position cannot tell two edges apart when their vertices
fall on the same position, which happens where the surface passes within rounding of a voxel;
a plane where that could happen is not used as a boundary (`_plane_is_ambiguous`).
`tests/sim/test_tsdf_slabs.py` compares with the whole-grid extraction.

The slabs' meshes are held until the last is made, in pages of their own; the result is then
filled from them, each slab's pages returned to the system once copied.
"""

from __future__ import annotations

import itertools
import mmap
from collections.abc import Iterable, Iterator
from typing import Any

import numpy as np
import numpy.typing as npt

from sim.open3d_any import o3c, o3d

__all__ = ["SLAB_BLOCKS", "block_grid", "extract_mesh", "mesh_in_slabs"]

_CPU = o3c.Device("CPU:0")

# Blocks per slab: 1,024 blocks of 8³ voxels cost about 16 MiB of scratch and copies; the
# result itself (float64 vertices, int32 triangles) is held once.
SLAB_BLOCKS = 1024

Vertices = npt.NDArray[np.float32]
Triangles = npt.NDArray[np.int32]
Points = npt.NDArray[np.float64]
Slab = tuple[Vertices, Triangles]


def block_grid(voxel_size: float, resolution: int, block_count: int) -> Any:
    """An empty CPU `VoxelBlockGrid` with float32 "tsdf" and "weight" per voxel."""
    return o3d.t.geometry.VoxelBlockGrid(
        attr_names=("tsdf", "weight"), attr_dtypes=(o3c.float32, o3c.float32),
        attr_channels=((1), (1)), voxel_size=voxel_size, block_resolution=resolution,
        block_count=block_count, device=_CPU,
    )


def mesh_in_slabs(grid: Any, voxel_size: float, weight_threshold: float,
                  slab_blocks: int = SLAB_BLOCKS) -> tuple[Points, Triangles]:
    """The marching-cubes mesh of `grid` (an Open3D `VoxelBlockGrid` on the CPU with float32
    "tsdf" and "weight" attributes, voxels of `voxel_size` metres): (V, 3) vertices (Open3D's
    float32 positions, as float64) and (F, 3) int32 triangles."""
    hashmap = grid.hashmap()
    rows = hashmap.active_buf_indices().numpy().astype(np.int64)
    keys = hashmap.key_tensor().numpy()[rows]
    # Zero-copy views of the value buffers: (capacity, r, r, r, 1), local x on axis 3.
    tsdf = grid.attribute("tsdf").numpy()
    weight = grid.attribute("weight").numpy()
    starts = _slab_starts(keys, tsdf, weight, rows, slab_blocks, voxel_size, weight_threshold)
    if len(starts) <= 1:
        vertices, triangles = extract_mesh(grid, weight_threshold)
        return vertices.astype(np.float64), triangles
    edges = [*starts, int(keys[:, 0].max()) + 1]
    resolution = tsdf.shape[1]

    def slab(lo: int, hi: int) -> Slab:
        inside = (keys[:, 0] >= lo) & (keys[:, 0] < hi)
        sub = _sub_grid(voxel_size, keys, rows, inside, keys[:, 0] == hi, tsdf, weight)
        return extract_mesh(sub, weight_threshold)

    # The slabs' meshes are held in pages of their own until all are made; the result is then
    # filled slab by slab, each slab's pages returned to the system once copied. The result's
    # pages become resident as they are written, so the peak is about the larger of the two.
    held = [slab(lo, hi) for lo, hi in itertools.pairwise(edges)]
    # Where Open3D puts a vertex of a plane voxel's y or z edge: voxel_size * (x + 0) in float32.
    planes = [np.float32(voxel_size) * np.float32(b * resolution) for b in edges[1:-1]]
    shared = [_shared_vertices(low, high, plane)
              for ((low, _), (high, _)), plane in zip(itertools.pairwise(held), planes,
                                                      strict=True)]
    out_v = np.empty((sum(len(v) for v, _ in held) - sum(len(lo) for lo, _ in shared), 3),
                     dtype=np.float64)
    out_t = np.empty((sum(len(t) for _, t in held), 3), dtype=np.int32)
    at_v = at_t = 0
    for vertices, triangles in _joined(_releasing(held), shared):
        out_v[at_v:at_v + len(vertices)] = vertices
        out_t[at_t:at_t + len(triangles)] = triangles
        at_v, at_t = at_v + len(vertices), at_t + len(triangles)
    return out_v, out_t


def _shared_vertices(low: Vertices, high: Vertices, plane: np.float32) -> tuple[
        npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Indices into `low` and `high` (two neighbouring slabs' vertices) of the vertices both
    made on the plane x = `plane` between them, paired one for one."""
    on_low = np.flatnonzero(low[:, 0] == plane)
    on_high = np.flatnonzero(high[:, 0] == plane)
    i, j = _pair_equal_rows(low[on_low], high[on_high])
    return on_low[i], on_high[j]


def _releasing(held: list[Slab]) -> Iterator[Slab]:
    """The slabs in order, each dropped from `held` as it is given."""
    held.reverse()
    while held:
        yield held.pop()


def _joined(slabs: Iterable[Slab], shared: list[tuple[npt.NDArray[np.int64],
                                                      npt.NDArray[np.int64]]],
            ) -> Iterator[tuple[Vertices, Triangles]]:
    """The slabs' meshes as consecutive parts of one mesh: a slab's vertices that `shared`
    pairs with the slab below's are dropped, and its triangles are given in the whole mesh's
    vertex indices."""
    below_index = np.zeros(0, dtype=np.int64)  # whole-mesh indices of the slab below's shared
    given = 0  # vertices given so far
    for k, (vertices, triangles) in enumerate(slabs):
        index = np.full(len(vertices), -1, dtype=np.int64)
        if k > 0:
            index[shared[k - 1][1]] = below_index
        own = index < 0
        n_own = int(np.count_nonzero(own))
        index[own] = given + np.arange(n_own)
        if k < len(shared):
            below_index = index[shared[k][0]]
        given += n_own
        yield vertices[own], index[triangles].astype(np.int32)


def _slab_starts(keys: npt.NDArray[np.int32], tsdf: npt.NDArray[np.float32],
                 weight: npt.NDArray[np.float32], rows: npt.NDArray[np.int64],
                 slab_blocks: int, voxel_size: float, weight_threshold: float) -> list[int]:
    """First block x of each slab: slabs of whole x-planes of blocks, at most `slab_blocks`
    blocks each where one plane is not larger, never starting at an ambiguous plane."""
    xs, counts = np.unique(keys[:, 0], return_counts=True)
    starts = [int(xs[0])]
    filled = 0
    for x, count in zip(xs.tolist(), counts.tolist(), strict=True):
        if filled and filled + count > slab_blocks \
                and not _plane_is_ambiguous(x, keys, tsdf, weight, rows, voxel_size,
                                            weight_threshold):
            starts.append(x)
            filled = 0
        filled += count
    return starts


def _plane_is_ambiguous(bx: int, keys: npt.NDArray[np.int32], tsdf: npt.NDArray[np.float32],
                        weight: npt.NDArray[np.float32], rows: npt.NDArray[np.int64],
                        voxel_size: float, weight_threshold: float) -> bool:
    """Whether two vertices on the plane x = `bx` * r could fall on the same position.

    The two slabs' vertices on the plane are paired by position; that pairing is exact when
    no two edges put a vertex at the same float32 position, which happens only where the
    surface passes within rounding of a voxel. Every edge that could carry a vertex on the
    plane (both ends weighted, a sign change) is placed here as Open3D places it, and the
    plane is ambiguous if any two coincide."""
    resolution = tsdf.shape[1]
    upper, lower = keys[:, 0] == bx, keys[:, 0] == bx - 1
    if not upper.any():
        return False
    yz = keys[upper | lower, 1:]
    y0, z0 = yz.min(axis=0)
    ny, nz = (yz.max(axis=0) - (y0, z0) + 1) * resolution
    here, after, before = (np.full((ny, nz), np.nan, dtype=np.float32) for _ in range(3))
    local = np.arange(resolution)
    for layer, x, out in ((upper, 0, here), (upper, 1, after), (lower, resolution - 1, before)):
        values = tsdf[rows[layer], :, :, x, 0].transpose(0, 2, 1)  # (block, y, z)
        weighed = np.greater(weight[rows[layer], :, :, x, 0].transpose(0, 2, 1),
                             weight_threshold)
        y = ((keys[layer, 1] - y0) * resolution)[:, None, None] + local[None, :, None]
        z = ((keys[layer, 2] - z0) * resolution)[:, None, None] + local[None, None, :]
        out[y, z] = np.where(weighed, values, np.nan)
    vs = np.float32(voxel_size)
    x_plane = np.float32(bx * resolution)
    gy = np.float32(y0 * resolution) + np.arange(ny, dtype=np.float32)
    gz = np.float32(z0 * resolution) + np.arange(nz, dtype=np.float32)
    grid_y, grid_z = np.meshgrid(gy, gz, indexing="ij")
    found: list[npt.NDArray[np.float32]] = []

    def edge(t_o: npt.NDArray[np.float32], t_e: npt.NDArray[np.float32]) -> tuple[
            npt.NDArray[np.bool_], npt.NDArray[np.float32]]:
        with np.errstate(invalid="ignore", divide="ignore"):
            crossing = (t_o < 0) != (t_e < 0)
            crossing &= ~np.isnan(t_o) & ~np.isnan(t_e)
            ratio = (np.float32(0.0) - t_o) / (t_e - t_o)
        return crossing, ratio

    # y and z edges within the plane
    crossing, ratio = edge(here[:-1, :], here[1:, :])
    ys = vs * (grid_y[:-1, :] + ratio)
    found.append(np.column_stack([ys[crossing], (vs * grid_z[:-1, :])[crossing]]))
    crossing, ratio = edge(here[:, :-1], here[:, 1:])
    zs = vs * (grid_z[:, :-1] + ratio)
    found.append(np.column_stack([(vs * grid_y[:, :-1])[crossing], zs[crossing]]))
    # x edges ending on the plane (from the lower slab) and starting on it
    for t_o, t_e, start in ((before, here, x_plane - np.float32(1.0)), (here, after, x_plane)):
        crossing, ratio = edge(t_o, t_e)
        on_plane = crossing & (vs * (start + ratio) == vs * x_plane)
        found.append(np.column_stack([(vs * grid_y)[on_plane], (vs * grid_z)[on_plane]]))
    points = _plane_keys(np.concatenate(found))
    return len(np.unique(points)) < len(points)


def _sub_grid(voxel_size: float, keys: npt.NDArray[np.int32], rows: npt.NDArray[np.int64],
              inside: npt.NDArray[np.bool_], layer: npt.NDArray[np.bool_],
              tsdf: npt.NDArray[np.float32], weight: npt.NDArray[np.float32]) -> Any:
    """A grid of the blocks `inside` and, weighted on their first x plane only, `layer`."""
    picked = np.concatenate([np.flatnonzero(inside), np.flatnonzero(layer)])
    resolution = tsdf.shape[1]
    sub = block_grid(voxel_size, resolution, max(len(picked), 1))
    buf, _ = sub.hashmap().activate(o3c.Tensor(np.ascontiguousarray(keys[picked])))
    target = buf.numpy().astype(np.int64)
    sub_tsdf = sub.attribute("tsdf").numpy()
    sub_weight = sub.attribute("weight").numpy()
    sub_tsdf[target] = tsdf[rows[picked]]
    sub_weight[target] = weight[rows[picked]]
    n_inside = int(np.count_nonzero(inside))
    sub_weight[target[n_inside:], :, :, 1:, :] = 0.0
    return sub


def extract_mesh(grid: Any, weight_threshold: float) -> tuple[Vertices, Triangles]:
    """Open3D's mesh of `grid`, copied into arrays of their own pages (`_own_pages`)."""
    try:
        mesh = grid.extract_triangle_mesh(weight_threshold)
    except RuntimeError:  # Open3D raises instead of returning an empty mesh
        mesh = None
    if mesh is None or "positions" not in mesh.vertex or "indices" not in mesh.triangle:
        return np.zeros((0, 3), dtype=np.float32), np.zeros((0, 3), dtype=np.int32)
    positions = mesh.vertex.positions.numpy()
    indices = mesh.triangle.indices.numpy()
    vertices = _own_pages(positions.shape, np.float32)
    triangles = _own_pages(indices.shape, np.int32)
    vertices[...] = positions
    triangles[...] = indices
    return vertices, triangles


def _own_pages(shape: tuple[int, ...], dtype: type[np.generic]) -> npt.NDArray[Any]:
    """An array in an anonymous mapping of its own, unmapped when the array is dropped: a few
    MiB freed on the heap stay resident, and the slabs' meshes are dropped one by one while
    the result is being filled."""
    nbytes = int(np.prod(shape)) * np.dtype(dtype).itemsize
    if nbytes == 0:
        return np.zeros(shape, dtype=dtype)
    return np.frombuffer(mmap.mmap(-1, nbytes), dtype=dtype).reshape(shape)


def _plane_keys(yz: npt.NDArray[np.float32]) -> npt.NDArray[np.uint64]:
    """One key per (N, 2) y, z position on a plane: the two float32s' bits (-0.0 as 0.0)."""
    bits = (yz + np.float32(0.0)).view(np.uint32).astype(np.uint64)
    return np.asarray((bits[:, 0] << np.uint64(32)) | bits[:, 1], dtype=np.uint64)


def _pair_equal_rows(a: Vertices, b: Vertices) -> tuple[npt.NDArray[np.int64],
                                                        npt.NDArray[np.int64]]:
    """Indices (i, j) pairing vertices of `a` with equal vertices of `b`, all on one x plane.
    On a boundary plane no two vertices of a slab coincide (`_plane_is_ambiguous`); should
    some, the k-th copy in `a` is paired with the k-th in `b`."""
    ka, kb = _plane_keys(a[:, 1:]), _plane_keys(b[:, 1:])
    if len(np.unique(ka)) == len(ka) and len(np.unique(kb)) == len(kb):
        _, i, j = np.intersect1d(ka, kb, assume_unique=True, return_indices=True)
        return i.astype(np.int64), j.astype(np.int64)
    ra, rb = _occurrence(ka), _occurrence(kb)
    both = np.concatenate([np.column_stack([ka, ra]), np.column_stack([kb, rb])])
    _, inverse = np.unique(both, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    _, i, j = np.intersect1d(inverse[:len(ka)], inverse[len(ka):], assume_unique=True,
                             return_indices=True)
    return i.astype(np.int64), j.astype(np.int64)


def _occurrence(keys: npt.NDArray[np.uint64]) -> npt.NDArray[np.uint64]:
    """How many equal keys come before each key."""
    order = np.argsort(keys, kind="stable")
    ordered = keys[order]
    starts = np.ones(len(keys), dtype=bool)
    starts[1:] = ordered[1:] != ordered[:-1]
    first = np.maximum.accumulate(np.where(starts, np.arange(len(keys)), 0))
    rank = np.empty(len(keys), dtype=np.uint64)
    rank[order] = np.arange(len(keys)) - first
    return rank
