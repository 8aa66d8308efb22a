"""Mesh F-score of ESM-Recon against ESM-IPP at each area's plateau, default preset.

    .venv/bin/python benchmarks/esm_fscore.py [--areas maze offices-a facility-a]
        [--seeds 0 1 2 3 4]

Target: ESM-Recon's mean F-score >= ESM-IPP's on at least 3 of MAZE, OFFICES A and FACILITY A
(5 runs each). The JSON is rewritten after every run, so an interrupted benchmark keeps the runs
it finished.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from areas import load_area, load_ground_truth
from benchmarks.common import peak_rss_mib, print_table, write_json
from planners.registry import make, spec
from sim.config import preset
from sim.episode import run_episode

PLANNERS = ("esm-ipp", "esm-recon")


def run_one(area_name: str, planner: str, seed: int, preset_name: str) -> dict[str, Any]:
    area = load_area(area_name)
    t0 = time.perf_counter()
    result = run_episode(area, load_ground_truth(area), make(planner), preset(preset_name), seed,
                         planner_name=spec(planner).id, preset_name=preset_name)
    s = result.surface
    return {
        "area": area_name, "planner": spec(planner).id, "seed": seed,
        "status": result.status.value, "reason": result.reason, "coverage": result.coverage,
        "collisions": result.collisions, "fscore": s.fscore, "precision": s.precision,
        "recall": s.recall, "rmse_m": s.rmse_m, "simulated_s": result.simulated_until,
        "wall_s": time.perf_counter() - t0,
    }


def summarise(runs: list[dict[str, Any]], areas: list[str]) -> dict[str, Any]:
    """Per area: each planner's mean F-score over its runs, and whether Recon >= IPP."""
    out: dict[str, Any] = {}
    for area in areas:
        means = {}
        for planner in PLANNERS:
            scores = [r["fscore"] for r in runs if r["area"] == area
                      and r["planner"] == spec(planner).id]
            means[planner] = (float(np.mean(scores)), len(scores)) if scores else (None, 0)
        ipp, recon = means["esm-ipp"][0], means["esm-recon"][0]
        out[area] = {"means": means,
                     "recon_ge_ipp": None if ipp is None or recon is None else recon >= ipp}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--areas", nargs="+", default=["maze", "offices-a", "facility-a"])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    parser.add_argument("--preset", default="default")
    parser.add_argument("--out", default="esm_fscore", help="JSON name in results/")
    args = parser.parse_args()
    runs: list[dict[str, Any]] = []
    command = "python benchmarks/esm_fscore.py " + " ".join(sys.argv[1:])
    for area in args.areas:
        for seed in args.seeds:
            for planner in PLANNERS:
                run = run_one(area, planner, seed, args.preset)
                runs.append(run)
                print(f"{area} {planner} seed {seed}: F-score {run['fscore']:.4f}, coverage "
                      f"{run['coverage']:.3f}, {run['status']}, {run['wall_s']:.0f} s wall",
                      flush=True)
                write_json(args.out, {"command": command, "preset": args.preset, "runs": runs,
                                      "summary": summarise(runs, args.areas),
                                      "peak_rss_mib": peak_rss_mib()})
    summary = summarise(runs, args.areas)
    rows = []
    for area in args.areas:
        s = summary[area]
        (ipp, n_ipp), (recon, n_recon) = s["means"]["esm-ipp"], s["means"]["esm-recon"]
        rows.append([area, f"{ipp:.4f} ({n_ipp})", f"{recon:.4f} ({n_recon})",
                     "yes" if s["recon_ge_ipp"] else "NO"])
    print_table(f"Mesh F-score at the plateau, preset {args.preset} (mean over runs)",
                ["area", "esm-ipp (runs)", "esm-recon (runs)", "recon >= ipp"], rows)
    wins = sum(1 for a in args.areas if summary[a]["recon_ge_ipp"])
    print(f"ESM-Recon >= ESM-IPP on {wins} of {len(args.areas)} areas (target: 3 of MAZE, "
          "OFFICES A, FACILITY A)")
    path = write_json(args.out, {"command": command, "preset": args.preset, "runs": runs,
                                 "summary": summary, "wins": wins,
                                 "peak_rss_mib": peak_rss_mib()})
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
