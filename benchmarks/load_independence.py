"""Does machine load change the score? Planners on MAZE, each flown twice alone and once beside
busy processes that take every core, with planning charged in CPU time (the default) and, for
comparison, in wall time.

For every planner and charge it prints the median charged planning time per call, quiet and
loaded, and the mean absolute difference of coverage and F-score between the loaded run and the
first quiet one, beside that between the two quiet runs. Targets (CPU charge): the loaded
median within 10 % of the quiet one, and the loaded difference at most 1.5x the quiet one.

    .venv/bin/python benchmarks/load_independence.py [--planners classic,rapid,...]
        [--seeds 0,1,2] [--seconds 300] [--charges cpu,wall]
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import statistics
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from areas import load_area, load_ground_truth
from benchmarks.common import print_table, write_json
from planners.registry import make
from sim.config import preset
from sim.episode import run_episode

DEFAULT_PLANNERS = "classic,rapid,splatplanner,nbvp,esm-ipp"


def _busy(stop: Any) -> None:
    x = 0
    while not stop.is_set():
        for i in range(20000):
            x ^= i * i


def _fly(planner: str, seed: int, seconds: float, charge: str) -> dict[str, float]:
    area = load_area("maze")
    cfg = preset("default").model_copy(update={"planning_time_charge": charge})
    r = run_episode(area, load_ground_truth(area), make(planner), cfg, seed, seconds=seconds)
    charged = [float(c) for c in r.charged_s]
    return {"coverage": r.coverage, "fscore": r.surface.fscore, "iterations": r.iterations,
            "charged_median_s": statistics.median(charged) if charged else 0.0}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--planners", default=DEFAULT_PLANNERS)
    parser.add_argument("--seeds", default="0,1,2")
    parser.add_argument("--seconds", type=float, default=300.0)
    parser.add_argument("--charges", default="cpu,wall")
    args = parser.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    rows, out = [], []
    for charge in args.charges.split(","):
        for planner in args.planners.split(","):
            _fly(planner, 0, 5.0, charge)  # loads and compiles what the planner needs
            runs: list[dict[str, Any]] = []
            for seed in seeds:
                quiet = [_fly(planner, seed, args.seconds, charge) for _ in range(2)]
                stop = mp.Event()
                busy = [mp.Process(target=_busy, args=(stop,)) for _ in range(os.cpu_count() or 2)]
                for p in busy:
                    p.start()
                try:
                    loaded = _fly(planner, seed, args.seconds, charge)
                finally:
                    stop.set()
                    for p in busy:
                        p.join()
                runs.append({"seed": seed, "quiet": quiet, "loaded": loaded})
            q_med = statistics.median(r["quiet"][0]["charged_median_s"] for r in runs)
            l_med = statistics.median(r["loaded"]["charged_median_s"] for r in runs)
            d = {}
            for metric in ("coverage", "fscore"):
                d[f"quiet_{metric}"] = statistics.mean(
                    abs(r["quiet"][1][metric] - r["quiet"][0][metric]) for r in runs)
                d[f"loaded_{metric}"] = statistics.mean(
                    abs(r["loaded"][metric] - r["quiet"][0][metric]) for r in runs)
            ratio = l_med / q_med if q_med > 0 else float("nan")
            rows.append([charge, planner, f"{1000 * q_med:.2f}", f"{1000 * l_med:.2f}",
                         f"{ratio:.2f}", f"{d['quiet_coverage']:.4f}",
                         f"{d['loaded_coverage']:.4f}", f"{d['quiet_fscore']:.4f}",
                         f"{d['loaded_fscore']:.4f}"])
            out.append({"charge": charge, "planner": planner, "quiet_charged_median_s": q_med,
                        "loaded_charged_median_s": l_med, **d, "runs": runs})
    print_table(f"Load independence on MAZE, {args.seconds:.0f} s, seeds {args.seeds}",
                ["charge", "planner", "quiet ms/call", "loaded ms/call", "ratio",
                 "|dcov| quiet", "|dcov| loaded", "|dF| quiet", "|dF| loaded"], rows)
    path = write_json("load_independence", {"seconds": args.seconds, "seeds": seeds,
                                            "results": out})
    print(f"\nwritten to {path}")


if __name__ == "__main__":
    main()
