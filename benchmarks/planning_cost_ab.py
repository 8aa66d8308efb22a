"""A planner's CPU time per `plan` call in this tree and in another, flown side by side.

    .venv/bin/python benchmarks/planning_cost_ab.py --baseline DIR [--planners classic]
        [--areas maze,warehouse,powerplant] [--seconds 300]

DIR is another checkout (a `git worktree` or an unpacked `git archive`). Each flight uses the
`exact` preset (planning is not charged to the clock, so both trees fly the same flight when
their planners decide alike), seed 0, in a fresh process running that tree's code; the two
trees' flights of one cell run at the same time, each pinned to a core of its own, so that both
see the same machine load. Per cell: the median and total CPU time of the `plan` calls in each
tree, their ratio, and whether the two flights are the same (coverage, path length, number of
plans and the vehicle's final pose, to the bit). Writes `benchmarks/results/planning_cost_ab.json`.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent.parent


def _child(planner: str, area_name: str, seconds: float) -> dict[str, Any]:
    """One exact flight, in this process, with the code of the tree it was started in."""
    import flybo  # noqa: F401  before NumPy: it pins the CPU kernels
    from areas import load_area, load_ground_truth
    from planners.registry import make, spec
    from sim.config import preset
    from sim.episode import run_episode

    area = load_area(area_name)
    truth = load_ground_truth(area)
    planner_id = spec(planner).id
    agent = make(planner_id)
    plan = agent.plan
    cpu: list[float] = []
    finals: list[list[float]] = []

    def timed(obs: Any) -> Any:
        finals[:] = [[*map(float, obs.pose.position), float(obs.pose.yaw)]]
        started = time.process_time()
        out = plan(obs)
        cpu.append(time.process_time() - started)
        return out

    agent.plan = timed  # type: ignore[method-assign]
    result = run_episode(area, truth, agent, preset("exact"), 0, planner_name=planner_id,
                         preset_name="exact", seconds=seconds)
    flight = [float(result.coverage).hex(), float(result.path_length_m).hex(), len(cpu),
              [float(v).hex() for v in (finals[0] if finals else [])]]
    return {"planner": planner_id, "area": area_name, "plans": len(cpu),
            "median_ms": 1000.0 * statistics.median(cpu) if cpu else 0.0,
            "total_s": float(sum(cpu)), "coverage": float(result.coverage), "flight": flight}


def _start(tree: Path, core: int | None, planner: str, area: str,
           seconds: float) -> subprocess.Popen[str]:
    cmd = [sys.executable, str(Path(__file__).resolve()), "--child-tree", str(tree),
           "--planners", planner, "--areas", area, "--seconds", str(seconds)]
    if core is not None:
        cmd = ["taskset", "-c", str(core), *cmd]
    return subprocess.Popen(cmd, cwd=tree, stdout=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONPATH": str(tree)})


def _result(process: subprocess.Popen[str]) -> dict[str, Any]:
    out, _ = process.communicate()
    if process.returncode:
        raise SystemExit(f"a flight failed (exit {process.returncode})")
    return dict(json.loads(out.strip().splitlines()[-1]))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", type=Path, required=False, default=None,
                        help="another tree's folder, flown beside this one")
    parser.add_argument("--planners", default="classic", help="comma-separated planner names")
    parser.add_argument("--areas", default="maze,warehouse,powerplant",
                        help="comma-separated areas")
    parser.add_argument("--seconds", type=float, default=300.0, help="simulated seconds")
    parser.add_argument("--child-tree", type=Path, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child_tree is not None:
        sys.path.insert(0, str(args.child_tree))
        print(json.dumps(_child(args.planners, args.areas, args.seconds)))
        return 0
    if args.baseline is None or not (args.baseline / "planners").is_dir():
        raise SystemExit(f"--baseline {args.baseline}: not a checkout (no planners/ folder in "
                         "it); give another tree's folder")
    sys.path.insert(0, str(HERE))
    from benchmarks.common import print_table, write_json

    cores = [0, 1] if (os.cpu_count() or 1) >= 2 else [None, None]
    cells: list[dict[str, Any]] = []
    for area in (a.strip() for a in args.areas.split(",")):
        for planner in (p.strip() for p in args.planners.split(",")):
            flying = (_start(HERE, cores[0], planner, area, args.seconds),
                      _start(args.baseline.resolve(), cores[1], planner, area, args.seconds))
            cell = {"this": _result(flying[0]), "baseline": _result(flying[1])}
            cells.append(cell)
            print(f"{planner} {area}: {cell['this']['median_ms']:.1f} vs "
                  f"{cell['baseline']['median_ms']:.1f} ms", flush=True)
    rows = []
    for cell in cells:
        this, base = cell["this"], cell["baseline"]
        cell["median_ratio"] = this["median_ms"] / max(base["median_ms"], 1e-9)
        cell["total_ratio"] = this["total_s"] / max(base["total_s"], 1e-9)
        cell["same_flight"] = this["flight"] == base["flight"]
        rows.append([this["planner"], this["area"], this["plans"],
                     f"{this['median_ms']:.1f}", f"{base['median_ms']:.1f}",
                     f"{cell['median_ratio']:.2f}", f"{this['total_s']:.1f}",
                     f"{base['total_s']:.1f}", f"{cell['total_ratio']:.2f}",
                     "yes" if cell["same_flight"] else "NO"])
    print_table(f"CPU time per plan call, this tree against {args.baseline} (exact preset, "
                f"seed 0, {args.seconds:g} s)",
                ["planner", "area", "plans", "median ms", "baseline ms", "ratio", "total s",
                 "baseline s", "ratio", "same flight"], rows)
    path = write_json("planning_cost_ab", {"baseline": str(args.baseline),
                                           "seconds": args.seconds, "cells": cells})
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
