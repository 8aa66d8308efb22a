"""The benchmark's metrics, each defined once (see `docs/metrics.md`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from sim.cell_lists import share_within

Points = npt.NDArray[np.floating]

# Distances are compared with tau plus this tolerance. The TSDF's voxel equals tau (5 cm), so
# marching-cubes vertices of a surface on the grid lie at exactly tau from the truth and a
# float's rounding would decide whether they count; 0.1 mm is far above any rounding of
# coordinates within a few hundred metres (float32's spacing at 200 m is 15 µm) and far below
# anything a reconstruction resolves (`docs/metrics.md` shows the sensitivity).
TIE_TOLERANCE_M = 1e-4


@dataclass(frozen=True)
class SurfaceScores:
    """Reconstruction quality against the ground-truth surface cloud.

    precision: share of reconstructed points within tau of the truth.
    recall: share of ground-truth points within tau of the reconstruction.
    fscore: harmonic mean of precision and recall (0 when both are 0).
    rmse_m: root mean square of reconstructed-point-to-truth distances, metres.
    """

    tau_m: float
    precision: float
    recall: float
    fscore: float
    rmse_m: float

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


def volumetric_efficiency(explored_volume_m3: float, time_s: float) -> float:
    """Explored volume per second, m³/s (0 at t = 0)."""
    return explored_volume_m3 / time_s if time_s > 0 else 0.0


def coverage(explored_volume_m3: float, observable_volume_m3: float) -> float:
    """Absolute volumetric coverage: explored over ground-truth observable volume."""
    return explored_volume_m3 / observable_volume_m3 if observable_volume_m3 > 0 else 0.0


def relative_coverage(volume_at_plateau_m3: float, best_volume_at_plateau_m3: float) -> float:
    """The paper's coverage: volume at the plateau over the best of any planner on the area."""
    if best_volume_at_plateau_m3 <= 0:
        return 0.0
    return volume_at_plateau_m3 / best_volume_at_plateau_m3


def fscore(precision: float, recall: float) -> float:
    return 2.0 * precision * recall / (precision + recall) if precision + recall > 0 else 0.0


def surface_recall(reconstruction: Points, truth: Points, tau_m: float) -> float:
    """Share of `truth` points (N, 3) with a `reconstruction` point (M, 3) within tau."""
    if len(truth) == 0:
        return 0.0
    if len(reconstruction) == 0:
        return 0.0
    # The bound is exclusive; nudge it so that a distance of exactly the bound counts.
    bound = float(np.nextafter(tau_m + TIE_TOLERANCE_M, np.inf))
    return share_within(reconstruction, truth, bound)


def sdf_surface_recall(
    sdf_at_truth: npt.NDArray[np.floating],
    weight_at_truth: npt.NDArray[np.floating],
    tau_m: float,
    min_weight: float,
) -> float:
    """Recall over time, read off the live TSDF: the share of ground-truth points where the fused
    signed distance (trilinear) is within tau and every surrounding sample has at least
    `min_weight`, i.e. where the surface being reconstructed passes within about tau.

    It agrees with `surface_recall` on the extracted surface (within half a percent on a fully
    explored MAZE) at a fraction of the cost, so it can be sampled often during a run.
    """
    if len(sdf_at_truth) == 0:
        return 0.0
    seen = (np.asarray(weight_at_truth) >= min_weight) & \
        (np.abs(sdf_at_truth) <= tau_m + TIE_TOLERANCE_M)
    return float(np.count_nonzero(seen)) / len(sdf_at_truth)


def surface_scores(
    reconstruction: Points,
    truth: Points,
    tau_m: float,
    distance_to_truth: Callable[[Points], npt.NDArray[np.floating]] | None = None,
) -> SurfaceScores:
    """Precision, recall, F-score at tau and RMSE of a reconstructed point set against the truth.

    Args:
        reconstruction: (M, 3) points on the reconstructed surface.
        truth: (N, 3) ground-truth surface cloud.
        distance_to_truth: distance from points (M, 3) to the true surface; by default the
            distance to the nearest point of `truth`. The episode runner passes the exact
            distance to the area's mesh, which the cloud only approximates (its spacing adds up
            to half a sample spacing to every distance).
    """
    if len(reconstruction) == 0 or len(truth) == 0:
        return SurfaceScores(tau_m, 0.0, 0.0, 0.0, float("nan"))
    if distance_to_truth is None:
        to_truth = cKDTree(truth).query(reconstruction, k=1)[0]
    else:
        to_truth = np.asarray(distance_to_truth(reconstruction), dtype=np.float64)
    precision = float(np.mean(to_truth <= tau_m + TIE_TOLERANCE_M))
    recall = surface_recall(reconstruction, truth, tau_m)
    # Summed in sorted order: Open3D extracts mesh vertices in a thread-dependent order, and the
    # score must not depend on it.
    squares = np.sort(to_truth)
    rmse = float(np.sqrt(np.mean(np.square(squares, out=squares))))
    return SurfaceScores(tau_m, precision, recall, fscore(precision, recall), rmse)


def path_length(positions: Points) -> float:
    """Length of the polyline through (N, 3) positions, metres."""
    if len(positions) < 2:
        return 0.0
    return float(np.sum(np.linalg.norm(np.diff(np.asarray(positions), axis=0), axis=1)))


def timing_summary(samples_ms: npt.ArrayLike) -> dict[str, float]:
    """Mean, median and max of per-iteration times in ms (zeros when there are none)."""
    arr = np.asarray(samples_ms, dtype=np.float64)
    if arr.size == 0:
        return {"mean": 0.0, "median": 0.0, "max": 0.0}
    return {"mean": float(arr.mean()), "median": float(np.median(arr)), "max": float(arr.max())}


def sample_mesh_surface(
    vertices: npt.NDArray[np.float64],
    triangles: npt.NDArray[np.int32],
    spacing_m: float,
    rng: np.random.Generator,
) -> npt.NDArray[np.float64]:
    """About one point per spacing² of area, uniformly on the mesh: (K, 3)."""
    if len(triangles) == 0:
        return np.zeros((0, 3))
    tri = vertices[triangles]
    areas = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    count = max(1, round(areas.sum() / spacing_m**2))
    choice = rng.choice(len(tri), size=count, p=areas / areas.sum())
    u, v = rng.random(count), rng.random(count)
    flip = u + v > 1.0
    u[flip], v[flip] = 1.0 - u[flip], 1.0 - v[flip]
    t = tri[choice]
    return np.asarray(t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0]))
