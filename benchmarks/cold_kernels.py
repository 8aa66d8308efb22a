"""Does an empty numba kernel cache change a run? Each planner flown on MAZE (default preset,
planning charged in CPU time) in a fresh process with an empty kernel cache, then again in a
fresh process with the cache the first filled.

For each planner and tree it prints the first planning call's charge cold and warm, the whole
run's charge, the CPU seconds of numba's compiler left out of the charge
(`planning_charge.compiling_left_out_s`; absent in trees that charged it) and the coverage.
`--baseline DIR` flies every pair a second time with another tree's code (an unpacked
`git archive`), in its own empty cache.

    .venv/bin/python benchmarks/cold_kernels.py [--planners classic,splatplanner]
        [--seconds 60] [--seed 0] [--baseline DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parents[1]


def _child(planner: str, seed: int, seconds: float) -> dict[str, Any]:
    """One flight, in this process, with the code of the tree it was started in."""
    import flybo  # noqa: F401  before NumPy: it pins the CPU kernels
    from areas import load_area, load_ground_truth
    from planners.registry import make, spec
    from sim.config import preset
    from sim.episode import run_episode

    area = load_area("maze")
    truth = load_ground_truth(area)
    planner_id = spec(planner).id
    result = run_episode(area, truth, make(planner_id), preset("default"), seed,
                         planner_name=planner_id, seconds=seconds)
    charge = result.to_json()["planning_charge"]
    return {"planner": planner_id, "coverage": result.coverage,
            "iterations": result.iterations,
            "first_charge_s": float(result.charged_s[0]) if len(result.charged_s) else 0.0,
            "total_charge_s": charge["total_s"],
            "compiling_left_out_s": charge.get("compiling_left_out_s")}


def _fly(tree: Path, cache: Path, planner: str, seed: int, seconds: float) -> dict[str, Any]:
    """One flight in a fresh process running `tree`'s code with numba's cache in `cache`."""
    cmd = [sys.executable, str(Path(__file__).resolve()), "--child-tree", str(tree),
           "--planners", planner, "--seed", str(seed), "--seconds", str(seconds)]
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    out = subprocess.run(cmd, cwd=tree, check=True, capture_output=True, text=True, env=env)
    return dict(json.loads(out.stdout.strip().splitlines()[-1]))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--planners", default="classic,splatplanner",
                        help="comma-separated planner names")
    parser.add_argument("--seconds", type=float, default=60.0, help="simulated seconds")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--baseline", type=Path, default=None,
                        help="another tree's folder, flown beside this one")
    parser.add_argument("--child-tree", type=Path, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child_tree is not None:
        # Every package from that tree (the measuring code above imports none of them).
        sys.path.insert(0, str(args.child_tree))
        print(json.dumps(_child(args.planners, args.seed, args.seconds)))
        return 0
    sys.path.insert(0, str(HERE))
    from benchmarks.common import checked_baseline, print_table, write_json

    baseline = checked_baseline(args.baseline)
    trees = [("this", HERE)] + ([("baseline", baseline)] if baseline else [])
    rows, out = [], []
    for planner in (p.strip() for p in args.planners.split(",")):
        for label, tree in trees:
            with tempfile.TemporaryDirectory(prefix="numba-cache-") as cache:
                cold = _fly(tree, Path(cache), planner, args.seed, args.seconds)
                warm = _fly(tree, Path(cache), planner, args.seed, args.seconds)
            left = [r["compiling_left_out_s"] for r in (cold, warm)]
            rows.append([label, cold["planner"],
                         f"{1000 * cold['first_charge_s']:.1f}",
                         f"{1000 * warm['first_charge_s']:.1f}",
                         f"{cold['total_charge_s']:.3f}", f"{warm['total_charge_s']:.3f}",
                         " / ".join("-" if v is None else f"{v:.2f}" for v in left),
                         f"{cold['coverage']:.4f}", f"{warm['coverage']:.4f}"])
            out.append({"tree": label, "cold": cold, "warm": warm})
            print(f"{label}: {cold['planner']} done", flush=True)
    print_table(f"An empty kernel cache on MAZE, {args.seconds:.0f} s, seed {args.seed}",
                ["tree", "planner", "1st call ms cold", "warm", "charged s cold", "warm",
                 "compiler left out s cold / warm", "coverage cold", "warm"], rows)
    path = write_json("cold_kernels", {"seconds": args.seconds, "seed": args.seed,
                                       "results": out})
    print(f"\nwritten to {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
