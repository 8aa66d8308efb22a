"""The slow parts of a replay, computed once per run in the background after the first frame.

- The ground-truth surface, subsampled for display (the full cloud has millions of points).
- The final mesh coloured by its distance to the ground truth. A 700 s MAZE mesh has 1.4 M
  triangles (35 MB): too much for a browser per tab, so the viewer shows it simplified by vertex
  clustering, and colours each shown vertex by its own distance to the truth cloud. The metrics
  of the run (`docs/metrics.md`) are computed on the full mesh, not on this one.
"""

from __future__ import annotations

import io
import threading
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from areas import load_ground_truth
from sim.open3d_any import o3d
from web.replay.source import RunData

TRUTH_DISPLAY_POINTS = 150_000
# The shown final mesh has about this many triangles at most (about 5 MB sent to each tab), and
# is never clustered finer than the minimum cell.
FINAL_MESH_MAX_FACES = 250_000
FINAL_MESH_MIN_CELL_M = 0.05
# Colours saturate at this distance: twice the surface metrics' threshold tau = 0.05 m.
DISTANCE_SATURATION_M = 0.10
# Green (on the truth) -> yellow (tau) -> red (2 tau or more).
_RAMP = np.array([[40, 180, 70], [240, 210, 40], [220, 40, 40]], dtype=np.float64)

Float32Array = npt.NDArray[np.float32]


@dataclass(frozen=True)
class ColouredMesh:
    """A mesh for display, coloured per vertex.

    Attributes:
        vertices: (V, 3) float32 world metres.
        faces: (F, 3) int32 indices into vertices.
        distances: (V,) float32 metres from each vertex to the nearest ground-truth point.
        colours: (V, 3) uint8 RGB.
        source_faces: triangles of the full mesh before simplification.
    """

    vertices: Float32Array
    faces: npt.NDArray[np.int32]
    distances: Float32Array
    colours: npt.NDArray[np.uint8]
    source_faces: int
    _glb: dict[float, bytes] = field(default_factory=dict, repr=False, compare=False)
    _glb_lock: threading.Lock = field(default_factory=threading.Lock, repr=False,
                                      compare=False)

    def glb(self, clip_z: float) -> bytes:
        """The mesh without the triangles above `clip_z`, as GLB bytes for the browser.

        Kept per clip height: exporting takes tens of milliseconds, and every tab of the run
        uses the same few heights.
        """
        with self._glb_lock:
            data = self._glb.get(clip_z)
            if data is None:
                import trimesh  # only for the GLB export of a replayed mesh

                keep = (self.vertices[self.faces, 2] <= clip_z).all(axis=1)
                mesh = trimesh.Trimesh(self.vertices, self.faces[keep], process=False,
                                       vertex_colors=self.colours)
                buffer = io.BytesIO()
                mesh.export(buffer, file_type="glb")
                data = self._glb[clip_z] = buffer.getvalue()
            return data


@dataclass(frozen=True)
class Extras:
    """Attributes:
    truth_points: (N, 3) float32, a seeded subsample of the perceivable ground-truth surface.
    final_mesh: the final mesh for display, or None when the run has none.
    """

    truth_points: Float32Array
    final_mesh: ColouredMesh | None


def distance_colours(distances: npt.NDArray[np.floating]) -> npt.NDArray[np.uint8]:
    """(N, 3) uint8 colours of distances (N,) in metres on the green-yellow-red ramp."""
    x = np.clip(np.asarray(distances, dtype=np.float64) / DISTANCE_SATURATION_M, 0.0, 1.0) * 2.0
    lo = np.minimum(x.astype(np.int64), 1)
    frac = (x - lo)[:, None]
    rgb = _RAMP[lo] * (1.0 - frac) + _RAMP[lo + 1] * frac
    return np.round(rgb).astype(np.uint8)


def cluster_mesh(vertices: npt.NDArray[np.floating], faces: npt.NDArray[np.integer],
                 cell: float) -> tuple[Float32Array, npt.NDArray[np.int32]]:
    """Vertex clustering: one vertex (the mean) per `cell`-sized cube; collapsed and repeated
    triangles are dropped. Vectorised because Open3D's version takes 4 s on a MAZE mesh.

    Returns:
        vertices (V', 3) float32 and faces (F', 3) int32.
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    if len(v) == 0 or len(f) == 0:
        return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32)
    cells = np.floor(v / cell).astype(np.int64)
    cells -= cells.min(axis=0)
    span = cells.max(axis=0) + 1
    keys = (cells[:, 0] * span[1] + cells[:, 1]) * span[2] + cells[:, 2]
    _, group, counts = np.unique(keys, return_inverse=True, return_counts=True)
    group = group.reshape(-1)
    sums = np.stack([np.bincount(group, weights=v[:, a]) for a in range(3)], axis=1)
    merged = sums.astype(np.float64) / counts[:, None]
    g = group[f]
    keep = (g[:, 0] != g[:, 1]) & (g[:, 1] != g[:, 2]) & (g[:, 0] != g[:, 2])
    g = g[keep]
    # Two faces over the same three clusters are one triangle (either winding: drawn two-sided).
    s = np.sort(g, axis=1)
    n = len(merged)
    _, first = np.unique((s[:, 0] * n + s[:, 1]) * n + s[:, 2], return_index=True)
    g = g[np.sort(first)]
    used, remap = np.unique(g, return_inverse=True)
    return merged[used].astype(np.float32), remap.reshape(-1, 3).astype(np.int32)


def display_cell(vertices: npt.NDArray[np.floating], faces: npt.NDArray[np.integer]) -> float:
    """Clustering cell giving about `FINAL_MESH_MAX_FACES` triangles: a surface of area A
    clustered at cell c keeps about A / c² vertices and twice as many triangles."""
    if len(faces) == 0:
        return FINAL_MESH_MIN_CELL_M
    tri = np.asarray(vertices, dtype=np.float64)[np.asarray(faces)]
    area = 0.5 * float(np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]),
                                      axis=1).sum())
    return max(FINAL_MESH_MIN_CELL_M, float(np.sqrt(2.0 * area / FINAL_MESH_MAX_FACES)))


def read_mesh(path: Path) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]:
    """(V, 3) vertices and (F, 3) faces of a PLY (or any mesh file Open3D reads)."""
    mesh = o3d.io.read_triangle_mesh(str(path))
    return (np.asarray(mesh.vertices, dtype=np.float64),
            np.asarray(mesh.triangles, dtype=np.int64))


def coloured_final_mesh(path: Path, tree: cKDTree) -> ColouredMesh:
    vertices, faces = read_mesh(path)
    shown, shown_faces = cluster_mesh(vertices, faces, display_cell(vertices, faces))
    distances, _ = tree.query(shown, k=1)
    distances = np.asarray(distances, dtype=np.float32)
    return ColouredMesh(shown, shown_faces, distances, distance_colours(distances), len(faces))


def default_clip_z(run: RunData) -> float:
    """Map layers are cut just under the top of the area: a ceiling would hide all below it."""
    return round(float(run.area.bounds_max[2]) - 1.5 * run.timeline.voxel_size, 2)


@dataclass(frozen=True)
class _AreaTruth:
    shown: Float32Array
    tree: cKDTree


# Trees of the areas last used; one of a large area holds hundreds of MB.
_TRUTHS_KEPT = 2
# Truth points in a tree at most: a 2 cm cloud of the largest areas has tens of millions, and a
# seeded subsample of this size keeps the spacing within a few cm on them (all of MAZE's).
TREE_MAX_POINTS = 8_000_000
_truths: dict[tuple[str, str | None, int], _AreaTruth] = {}
_truths_lock = threading.Lock()


def _area_truth(run: RunData) -> _AreaTruth:
    """The truth subsample and search tree of the run's area, built once for all its runs: the
    tree of a large area takes seconds of CPU that would slow every tab."""
    area = run.area
    key = (area.name, area.cache_key, len(area.triangles))
    with _truths_lock:
        found = _truths.get(key)
        if found is None:
            truth = load_ground_truth(area).surface_points
            rng = np.random.default_rng(0)  # the same subsample in every tab
            shown = truth
            if len(truth) > TRUTH_DISPLAY_POINTS:
                pick = rng.choice(len(truth), TRUTH_DISPLAY_POINTS, replace=False)
                shown = truth[np.sort(pick)]
            if len(truth) > TREE_MAX_POINTS:
                truth = truth[np.sort(rng.choice(len(truth), TREE_MAX_POINTS, replace=False))]
            tree = cKDTree(np.asarray(truth, dtype=np.float64), balanced_tree=False,
                           compact_nodes=False)  # builds faster; queries are few
            while len(_truths) >= _TRUTHS_KEPT:
                _truths.pop(next(iter(_truths)))
            found = _truths[key] = _AreaTruth(np.asarray(shown, dtype=np.float32), tree)
        return found


def compute_extras(run: RunData) -> Extras:
    truth = _area_truth(run)
    mesh = None
    if run.mesh_path is not None:
        mesh = coloured_final_mesh(run.mesh_path, truth.tree)
        mesh.glb(default_clip_z(run))  # the first tab reaching the end finds it ready
    return Extras(truth.shown, mesh)
