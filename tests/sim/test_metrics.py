"""The benchmark's metrics on hand-computed cases."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import open3d as o3d
import pytest
from scipy.spatial import cKDTree

from sim.metrics import (
    SurfaceScores,
    coverage,
    fscore,
    path_length,
    relative_coverage,
    sample_mesh_surface,
    surface_recall,
    surface_scores,
    timing_summary,
    volumetric_efficiency,
)

FloatArray = npt.NDArray[np.float64]

TAU = 0.1
TRUTH = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [3.0, 0.0, 0.0]])
RECONSTRUCTION = np.array(
    [
        [0.0, 0.0, 0.05],  # 0.05 from truth 0
        [1.0, 0.08, 0.0],  # 0.08 from truth 1
        [2.5, 0.0, 0.3],  # sqrt(0.25 + 0.09) from truths 2 and 3
    ]
)


def test_surface_scores_by_hand() -> None:
    scores = surface_scores(RECONSTRUCTION, TRUTH, TAU)
    assert isinstance(scores, SurfaceScores)
    assert scores.tau_m == TAU
    assert scores.precision == pytest.approx(2.0 / 3.0)
    assert scores.recall == pytest.approx(2.0 / 4.0)
    # 2 * (2/3) * (1/2) / (2/3 + 1/2) = 4/7
    assert scores.fscore == pytest.approx(4.0 / 7.0)
    assert scores.rmse_m == pytest.approx(math.sqrt((0.05**2 + 0.08**2 + 0.34) / 3.0))
    assert scores.as_dict() == {
        "tau_m": TAU,
        "precision": scores.precision,
        "recall": scores.recall,
        "fscore": scores.fscore,
        "rmse_m": scores.rmse_m,
    }


def test_surface_scores_with_an_exact_distance() -> None:
    """Precision and RMSE use the given distance to the true surface; recall the cloud."""
    tree = cKDTree(TRUTH)
    same = surface_scores(RECONSTRUCTION, TRUTH, TAU, lambda p: tree.query(p)[0])
    assert same == surface_scores(RECONSTRUCTION, TRUTH, TAU)
    exact = surface_scores(RECONSTRUCTION, TRUTH, TAU, lambda p: np.zeros(len(p)))
    assert exact.precision == 1.0
    assert exact.rmse_m == 0.0
    assert exact.recall == same.recall


def test_surface_scores_depend_on_tau() -> None:
    loose = surface_scores(RECONSTRUCTION, TRUTH, 0.6)
    assert loose.precision == 1.0
    assert loose.recall == 1.0
    assert loose.fscore == 1.0
    tight = surface_scores(RECONSTRUCTION, TRUTH, 0.06)
    assert tight.precision == pytest.approx(1.0 / 3.0)
    assert tight.recall == pytest.approx(1.0 / 4.0)
    assert tight.fscore == pytest.approx(2.0 * (1 / 3) * (1 / 4) / (1 / 3 + 1 / 4))
    # RMSE does not depend on tau.
    assert tight.rmse_m == loose.rmse_m


def test_perfect_reconstruction() -> None:
    scores = surface_scores(TRUTH.copy(), TRUTH, 0.01)
    assert (scores.precision, scores.recall, scores.fscore, scores.rmse_m) == (1.0, 1.0, 1.0, 0.0)


def test_empty_inputs() -> None:
    empty = np.zeros((0, 3))
    for rec, truth in ((empty, TRUTH), (RECONSTRUCTION, empty), (empty, empty)):
        scores = surface_scores(rec, truth, TAU)
        assert (scores.precision, scores.recall, scores.fscore) == (0.0, 0.0, 0.0)
        assert math.isnan(scores.rmse_m)
        assert scores.tau_m == TAU
        assert surface_recall(rec, truth, TAU) == 0.0


def test_surface_recall() -> None:
    assert surface_recall(RECONSTRUCTION, TRUTH, TAU) == pytest.approx(0.5)
    # Recall is not symmetric: every reconstructed point has truth within 0.6 ...
    assert surface_recall(TRUTH, RECONSTRUCTION, 0.6) == 1.0
    # ... but only one truth point (the first) is within 0.06 of the reconstruction.
    assert surface_recall(RECONSTRUCTION, TRUTH, 0.06) == pytest.approx(0.25)
    # A single reconstructed point near truth 3 recalls one in four.
    assert surface_recall(np.array([[3.0, 0.01, 0.0]]), TRUTH, TAU) == pytest.approx(0.25)


def test_fscore() -> None:
    assert fscore(0.0, 0.0) == 0.0
    assert fscore(1.0, 0.0) == 0.0
    assert fscore(1.0, 1.0) == 1.0
    assert fscore(0.5, 1.0) == pytest.approx(2.0 / 3.0)
    assert fscore(0.8, 0.4) == pytest.approx(2 * 0.32 / 1.2)


def test_coverage_and_efficiency() -> None:
    assert coverage(30.0, 120.0) == 0.25
    assert coverage(120.0, 120.0) == 1.0
    assert coverage(10.0, 0.0) == 0.0
    assert relative_coverage(45.0, 60.0) == 0.75
    assert relative_coverage(60.0, 60.0) == 1.0
    assert relative_coverage(45.0, 0.0) == 0.0
    assert relative_coverage(45.0, -1.0) == 0.0
    assert volumetric_efficiency(120.0, 60.0) == 2.0
    assert volumetric_efficiency(120.0, 0.0) == 0.0
    assert volumetric_efficiency(0.0, 10.0) == 0.0


def test_path_length() -> None:
    assert path_length(np.array([[0.0, 0.0, 0.0], [3.0, 4.0, 0.0]])) == pytest.approx(5.0)
    # The two legs of the 3-4-5 triangle.
    assert path_length(np.array([[0.0, 0.0, 0.0], [3.0, 0.0, 0.0], [3.0, 4.0, 0.0]])) == (
        pytest.approx(7.0)
    )
    # Out and back, in 3D, with a repeated point.
    there_and_back = np.array([[1.0, 1.0, 1.0], [1.0, 4.0, 5.0], [1.0, 4.0, 5.0], [1.0, 1.0, 1.0]])
    assert path_length(there_and_back) == pytest.approx(10.0)
    assert path_length(np.array([[1.0, 2.0, 3.0]])) == 0.0
    assert path_length(np.zeros((0, 3))) == 0.0


def test_timing_summary() -> None:
    assert timing_summary([1.0, 2.0, 3.0, 10.0]) == {"mean": 4.0, "median": 2.5, "max": 10.0}
    assert timing_summary(np.array([7.5])) == {"mean": 7.5, "median": 7.5, "max": 7.5}
    assert timing_summary([]) == {"mean": 0.0, "median": 0.0, "max": 0.0}


def box_mesh(size: tuple[float, float, float]) -> tuple[FloatArray, npt.NDArray[np.int32]]:
    mesh = o3d.geometry.TriangleMesh.create_box(*size)
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.triangles, dtype=np.int32)


def test_sample_mesh_surface_density_on_a_square() -> None:
    vertices = np.array([[0.0, 0.0, 1.0], [2.0, 0.0, 1.0], [2.0, 3.0, 1.0], [0.0, 3.0, 1.0]])
    triangles = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int32)
    points = sample_mesh_surface(vertices, triangles, 0.1, np.random.default_rng(0))
    assert points.shape[1] == 3
    assert abs(len(points) - 600) <= 1  # 6 m² / 0.01 m²
    assert np.all(points[:, 2] == 1.0)
    assert points[:, 0].min() >= 0.0 and points[:, 0].max() <= 2.0
    assert points[:, 1].min() >= 0.0 and points[:, 1].max() <= 3.0
    # Uniform: each half of the square holds about half the points.
    assert np.mean(points[:, 0] < 1.0) == pytest.approx(0.5, abs=0.06)
    assert np.mean(points[:, 1] < 1.5) == pytest.approx(0.5, abs=0.06)


def test_sample_mesh_surface_on_a_box() -> None:
    size = (4.0, 4.0, 3.0)
    vertices, triangles = box_mesh(size)
    points = sample_mesh_surface(vertices, triangles, 0.1, np.random.default_rng(1))
    area = 2 * (4 * 4 + 4 * 3 + 4 * 3)  # 80 m²
    assert abs(len(points) - area / 0.01) <= 1
    # Every point lies on a face of the box.
    to_face = np.minimum(points, np.array(size) - points)
    assert np.all(to_face.min(axis=1) < 1e-9)
    assert np.all(to_face > -1e-9)
    # Faces get points in proportion to their area: the floor has 16 / 80 of it.
    on_floor = np.abs(points[:, 2]) < 1e-9
    assert float(np.mean(on_floor)) == pytest.approx(0.2, abs=0.02)
    on_wall_x0 = np.abs(points[:, 0]) < 1e-9
    assert float(np.mean(on_wall_x0)) == pytest.approx(0.15, abs=0.02)


def test_sample_mesh_surface_is_seeded_and_handles_edge_cases() -> None:
    vertices, triangles = box_mesh((1.0, 1.0, 1.0))
    a = sample_mesh_surface(vertices, triangles, 0.2, np.random.default_rng(5))
    b = sample_mesh_surface(vertices, triangles, 0.2, np.random.default_rng(5))
    assert np.array_equal(a, b)
    assert abs(len(a) - 150) <= 1  # 6 m² / 0.04 m², truncated to an integer count
    # At least one point, however coarse the spacing.
    assert sample_mesh_surface(vertices, triangles, 100.0, np.random.default_rng(0)).shape == (1, 3)
    empty = sample_mesh_surface(
        vertices, np.zeros((0, 3), dtype=np.int32), 0.1, np.random.default_rng(0)
    )
    assert empty.shape == (0, 3)
