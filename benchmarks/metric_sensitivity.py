"""How the surface metrics move with tau and with the vertices' float rounding.

The TSDF's voxel equals tau (5 cm), so marching-cubes vertices of surfaces on the grid lie at
exactly tau from the truth. Without a tolerance, precision then depends on whether a vertex's
coordinates were rounded to float32 or float64, and jumps between tau = 4.99 and 5.01 cm; the
metrics count distances up to tau + `TIE_TOLERANCE_M` (0.1 mm), which no rounding reaches.

    .venv/bin/python benchmarks/metric_sensitivity.py [--area offices-a] [--seconds 150]
"""

from __future__ import annotations

import argparse
import sys
from functools import partial
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from areas import load_area, load_ground_truth
from benchmarks.common import print_table, write_json
from planners.registry import make
from sim import metrics
from sim.config import preset
from sim.episode import run_episode
from sim.mesh_distance import distance_to_mesh


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--area", default="offices-a")
    parser.add_argument("--planner", default="classic")
    parser.add_argument("--seconds", type=float, default=150.0)
    args = parser.parse_args()
    area = load_area(args.area)
    truth = load_ground_truth(area)
    cfg = preset("exact")
    result = run_episode(area, truth, make(args.planner), cfg, 0, seconds=args.seconds)
    to_mesh = partial(distance_to_mesh, area.vertices, area.triangles)
    cloud = truth.surface.sample(cfg.final_recall_points)
    rows, out = [], []
    tolerance = metrics.TIE_TOLERANCE_M
    for tol in (0.0, tolerance):
        metrics.TIE_TOLERANCE_M = tol
        for dtype in (np.float32, np.float64):
            verts = result.mesh_vertices.astype(dtype).astype(np.float64)
            for tau in (0.0499, 0.05, 0.0501):
                s = metrics.surface_scores(verts, cloud, tau, to_mesh)
                rows.append([f"{1000 * tol:.1f}", np.dtype(dtype).name, f"{100 * tau:.2f}",
                             f"{s.precision:.5f}", f"{s.recall:.5f}", f"{s.fscore:.5f}"])
                out.append({"tolerance_m": tol, "dtype": np.dtype(dtype).name, "tau_m": tau,
                            "precision": s.precision, "recall": s.recall, "fscore": s.fscore})
    metrics.TIE_TOLERANCE_M = tolerance
    print_table(f"Surface metrics of {args.planner} on {args.area} ({args.seconds:.0f} s, exact)",
                ["tolerance mm", "vertices", "tau cm", "precision", "recall", "F-score"], rows)
    print(f"\nwritten to {write_json('metric_sensitivity', {'area': args.area, 'rows': out})}")


if __name__ == "__main__":
    main()
