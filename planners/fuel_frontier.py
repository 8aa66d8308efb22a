"""FUEL's frontier information structure (Zhou et al., RA-L 2021, Sec. IV; the public code's
`active_perception/frontier_finder.cpp`), on the framework's map.

- **Clusters**: 26-connected groups of frontier voxels with more than `cluster_min` voxels
  (region growing in `expandFrontier`), voxels near the floor left out; a group with a
  down-sampled cell farther than `cluster_size_xy` horizontally from its mean is cut in two
  across its first horizontal principal component, recursively (`splitHorizontally`).
- **Down-sampling**: the mean of the voxels in each cube of `down_sample` voxels (PCL's voxel
  grid filter); coverage and yaws are computed on these cells.
- **Viewpoints**: positions on horizontal circles around the cluster's mean (radii
  `candidate_rmin`..`candidate_rmax` in `candidate_rnum` steps, every `candidate_dphi`), each
  with the mean yaw toward the cluster's cells and its coverage, the number of down-sampled
  cells in the camera's view with a line of sight through known free voxels; those covering more
  than `min_visib_num` cells are kept, best coverage first (`sampleViewpoints`,
  `countVisibleCells`). A viewpoint must stand in the framework's traversable space (FUEL: not
  in inflated obstacles and `min_candidate_clearance` from unknown voxels).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy import ndimage

from planners.search import BoolGrid, IndexArray
from planners.viewpoints import lines_clear
from sim.camera import CameraConfig
from sim.map_view import MapView

FloatArray = npt.NDArray[np.float64]

_CONNECT_26 = np.ones((3, 3, 3), dtype=bool)


@dataclass(frozen=True)
class Viewpoints:
    """Viewpoints of one cluster, best coverage first.

    Attributes:
        positions: (V, 3) world metres.
        yaws: (V,) radians in [-pi, pi].
        visible: (V,) down-sampled cells each one covers.
    """

    positions: FloatArray
    yaws: FloatArray
    visible: npt.NDArray[np.int64]

    def __len__(self) -> int:
        return len(self.yaws)

    def take(self, keep: npt.NDArray[np.bool_] | IndexArray) -> Viewpoints:
        return Viewpoints(self.positions[keep], self.yaws[keep], self.visible[keep])


@dataclass(frozen=True)
class Cluster:
    """A frontier cluster of the structure.

    Attributes:
        voxels: (K, 3) int64 frontier voxels.
        average: (3,) mean of their centres, world metres.
        cells: (M, 3) down-sampled cells, world metres.
    """

    voxels: IndexArray
    average: FloatArray
    cells: FloatArray


def downsample(points: FloatArray, leaf_m: float) -> FloatArray:
    """(M, 3) the mean of the `points` (N, 3) inside each cube of side `leaf_m` (a grid aligned
    with the world origin, as PCL's voxel grid filter), cubes in lexicographic order."""
    if len(points) == 0:
        return np.zeros((0, 3))
    key = np.floor(points / leaf_m).astype(np.int64)
    key -= key.min(axis=0)
    span = key.max(axis=0) + 1
    # One integer per cube, in lexicographic order of the cubes (faster than rows in unique).
    code = (key[:, 0] * span[1] + key[:, 1]) * span[2] + key[:, 2]
    _, inverse, counts = np.unique(code, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    sums = np.stack([np.bincount(inverse, points[:, a], len(counts)) for a in range(3)], axis=1)
    out: FloatArray = sums / counts[:, None]
    return out


def split_horizontally(voxels: IndexArray, points: FloatArray, leaf_m: float,
                       size_xy_m: float) -> list[IndexArray]:
    """Pieces of one cluster (voxels (K, 3) with centres `points`) such that every piece's
    down-sampled cells lie within `size_xy_m` horizontally of the piece's mean: a piece that
    does not is halved across its first horizontal principal component (the covariance of its
    cells about the mean of its voxels, as FUEL's `splitHorizontally`)."""
    done: list[IndexArray] = []
    todo = [np.arange(len(voxels))]
    while todo:
        rows = todo.pop()
        pts = points[rows]
        mean = pts[:, :2].mean(axis=0)
        cells = downsample(pts, leaf_m)[:, :2] - mean
        if len(rows) < 2 or np.max(np.linalg.norm(cells, axis=1)) <= size_xy_m:
            done.append(voxels[rows])
            continue
        cov = cells.T @ cells / len(cells)
        _, vectors = np.linalg.eigh(cov)  # ascending eigenvalues: the last is the first PC
        side = (pts[:, :2] - mean) @ vectors[:, -1] >= 0.0
        if side.all() or not side.any():
            done.append(voxels[rows])
            continue
        todo.extend([rows[~side], rows[side]])
    return done


def clusters(view: MapView, cluster_min: int, size_xy_m: float, down_sample: int,
             excluded: BoolGrid | None = None, min_z_m: float | None = None,
             cache: dict[bytes, list[Cluster]] | None = None) -> list[Cluster]:
    """The frontier clusters of the current map (see the module's docstring).

    Args:
        cluster_min: a connected group needs more voxels than this (before it is split).
        size_xy_m: the horizontal half-size a cluster is split beyond.
        down_sample: the down-sampling cube's side, in voxels.
        excluded: frontier voxels left out (given up).
        min_z_m: frontier voxels with centres below this height are left out.
        cache: the pieces of each connected group by its voxels, from the previous call; a
            group that did not change is not split again. Left holding this call's groups.
    """
    mask = view.frontier if excluded is None else view.frontier & ~excluded
    if min_z_m is not None:
        below = math.ceil((min_z_m - view.origin[2]) / view.voxel_size - 0.5)
        if below > 0:
            mask = mask.copy()
            mask[:, :, :min(below, mask.shape[2])] = False
    labels, n = ndimage.label(mask, structure=_CONNECT_26)
    if n == 0:
        return []
    voxels = np.argwhere(labels)
    lab = labels[voxels[:, 0], voxels[:, 1], voxels[:, 2]]
    order = np.argsort(lab, kind="stable")
    voxels, lab = voxels[order], lab[order]
    sizes = np.bincount(lab, minlength=n + 1)[1:]
    groups = np.split(voxels, np.cumsum(sizes)[:-1])
    leaf = view.voxel_size * down_sample
    out: list[Cluster] = []
    kept: dict[bytes, list[Cluster]] = {}
    for group, size in zip(groups, sizes, strict=True):
        if size <= cluster_min:
            continue
        group = group.astype(np.int64)
        key = group.tobytes()
        pieces = cache.get(key) if cache is not None else None
        if pieces is None:
            pieces = []
            for piece in split_horizontally(group, view.index_to_world(group), leaf, size_xy_m):
                points = view.index_to_world(piece)
                pieces.append(Cluster(piece, points.mean(axis=0), downsample(points, leaf)))
        kept[key] = pieces
        out.extend(pieces)
    if cache is not None:
        cache.clear()
        cache.update(kept)
    return out


def mean_yaws(positions: FloatArray, cells: FloatArray) -> FloatArray:
    """(V,) for each position, the mean yaw toward the cells, as FUEL averages it: the signed
    angle of each cell's direction from the first cell's (sign by the vertical of their cross
    product), averaged over all cells, plus the first cell's heading."""
    dirs = cells[None, :, :] - positions[:, None, :]
    dirs /= np.maximum(np.linalg.norm(dirs, axis=2, keepdims=True), 1e-12)
    ref = dirs[:, :1, :]
    angle = np.arccos(np.clip(np.sum(dirs * ref, axis=2), -1.0, 1.0))
    cross_z = ref[:, :, 0] * dirs[:, :, 1] - ref[:, :, 1] * dirs[:, :, 0]
    angle = np.where(cross_z < 0.0, -angle, angle)
    yaw = angle.mean(axis=1) + np.arctan2(ref[:, 0, 1], ref[:, 0, 0])
    wrapped: FloatArray = np.arctan2(np.sin(yaw), np.cos(yaw))
    return wrapped


def in_view(positions: FloatArray, yaws: FloatArray, cells: FloatArray,
            camera: CameraConfig) -> npt.NDArray[np.bool_]:
    """(V, M) whether each cell lies in the level camera's frustum at each pose."""
    off = cells[None, :, :] - positions[:, None, :]
    c, s = np.cos(yaws)[:, None], np.sin(yaws)[:, None]
    forward = off[:, :, 0] * c + off[:, :, 1] * s
    left = -off[:, :, 0] * s + off[:, :, 1] * c
    dist = np.linalg.norm(off, axis=2)
    inside: npt.NDArray[np.bool_] = (
        (forward > 0.0)
        & (np.abs(left) <= forward * math.tan(math.radians(camera.fov_h_deg) / 2.0))
        & (np.abs(off[:, :, 2]) <= forward * math.tan(math.radians(camera.fov_v_deg) / 2.0))
        & (dist <= camera.max_range_m)
    )
    return inside


def coverage(view: MapView, opaque: BoolGrid, positions: FloatArray, yaws: FloatArray,
             cells: FloatArray, camera: CameraConfig) -> npt.NDArray[np.int64]:
    """(V,) cells in view of each pose whose line of sight crosses no `opaque` voxel (FUEL:
    occupied or unknown) between the cell's voxel and the eye's."""
    seen = in_view(positions, yaws, cells, camera)
    v, m = np.nonzero(seen)
    counts = np.zeros(len(positions), dtype=np.int64)
    if len(v) == 0:
        return counts
    eye = (positions[v] - view.origin) / view.voxel_size
    cell = (cells[m] - view.origin) / view.voxel_size
    clear = lines_clear(opaque, np.ascontiguousarray(cell), np.ascontiguousarray(eye))
    np.add.at(counts, v[clear], 1)
    return counts


def sample_offsets(r_min: float, r_max: float, r_num: int, dphi: float) -> FloatArray:
    """(R * P, 3) offsets on horizontal circles: `r_num` + 1 radii from `r_min` to `r_max`,
    angles from -pi every `dphi` below pi (FUEL's loops)."""
    radii = np.linspace(r_min, r_max, r_num + 1) if r_num > 0 else np.array([r_min])
    phis = -math.pi + dphi * np.arange(math.ceil(2.0 * math.pi / dphi - 1e-6))
    rr, pp = np.meshgrid(radii, phis, indexing="ij")
    return np.stack([rr * np.cos(pp), rr * np.sin(pp), np.zeros_like(rr)], axis=-1).reshape(-1, 3)


def sample_viewpoints(view: MapView, cluster: Cluster, offsets: FloatArray, opaque: BoolGrid,
                      camera: CameraConfig, min_visib_num: int) -> Viewpoints:
    """The cluster's viewpoints: traversable positions at `offsets` from its mean, looking
    along their mean yaw toward its cells, covering more than `min_visib_num` cells, best
    coverage first (stable: sampling order among equals)."""
    pos = cluster.average[None, :] + offsets
    idx = view.world_to_index(pos)
    shape = np.array(view.shape)
    ok = np.all((idx >= 0) & (idx < shape), axis=1)
    ok[ok] = view.traversable[idx[ok, 0], idx[ok, 1], idx[ok, 2]]
    pos = pos[ok]
    if len(pos) == 0 or len(cluster.cells) == 0:
        return Viewpoints(np.zeros((0, 3)), np.zeros(0), np.zeros(0, dtype=np.int64))
    yaws = mean_yaws(pos, cluster.cells)
    visible = coverage(view, opaque, pos, yaws, cluster.cells, camera)
    keep = visible > min_visib_num
    order = np.argsort(-visible[keep], kind="stable")
    return Viewpoints(pos[keep][order], yaws[keep][order], visible[keep][order])
