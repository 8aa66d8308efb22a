"""What the frontier clusters cost a planner per call, over one flight, and against another tree.

    .venv/bin/python benchmarks/frontier_clusters.py [--area offices-c] [--seconds 600]
        [--planner classic] [--preset exact] [--baseline DIR] [--rounds 2] [--out NAME]

Each flight runs alone in a fresh process (seed 0) and times every call of
`FrontierTracker.clusters` (the frontier update since the last call, the components, their
cells and the clusters' sums), with a digest of what each call returned. `--baseline DIR` flies
the same flight with the code of another tree (an unpacked `git archive` of an earlier commit),
the two trees alternating for `--rounds` rounds, and prints the ratio of their clustering times
measured in this one invocation. With the `exact` preset both trees fly the same flight, so the
digests must agree: the clusters are the same, only their cost differs.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent.parent


def _child(area_name: str, seconds: float, planner: str, preset_name: str) -> dict[str, Any]:
    """Fly once with the tree on `sys.path`, timing every clusters call."""
    import flybo  # noqa: F401  before NumPy loads: it pins the CPU kernels
    import sim.frontiers as frontiers
    from areas import load_area, load_ground_truth
    from planners.registry import make, spec
    from sim.config import preset
    from sim.episode import run_episode

    area = load_area(area_name)
    truth = load_ground_truth(area)
    # A short flight first, so that every kernel is compiled or loaded from its cache.
    run_episode(area, truth, make(planner), preset(preset_name), 0, seconds=10.0)
    original = frontiers.FrontierTracker.clusters
    calls: list[tuple[float, int]] = []
    digest = hashlib.sha256()

    def timed(self: Any, min_size: int = 5, max_extent_m: float = 3.0) -> Any:
        start = time.perf_counter()
        result = original(self, min_size, max_extent_m)
        calls.append((time.perf_counter() - start, int(self.count)))
        for cluster in result:
            digest.update(cluster.indices.tobytes())
            digest.update(cluster.centroid.tobytes())
        return result

    frontiers.FrontierTracker.clusters = timed  # type: ignore[method-assign]
    result = run_episode(area, truth, make(planner), preset(preset_name), 0, seconds=seconds,
                         planner_name=spec(planner).id, preset_name=preset_name)
    times = [c[0] * 1e3 for c in calls]
    return {"area": area_name, "planner": result.planner, "preset": preset_name,
            "simulated_until": result.simulated_until, "calls": len(calls),
            "total_ms": sum(times), "median_ms": statistics.median(times),
            "max_ms": max(times),
            "median_frontier_voxels": statistics.median(c[1] for c in calls),
            "digest": digest.hexdigest()}


def _fly(tree: Path, args: argparse.Namespace) -> dict[str, Any]:
    cmd = [sys.executable, str(HERE / "benchmarks" / "frontier_clusters.py"),
           "--child-tree", str(tree), "--area", args.area, "--seconds", str(args.seconds),
           "--planner", args.planner, "--preset", args.preset]
    out = subprocess.run(cmd, cwd=tree, check=True, capture_output=True, text=True)
    return dict(json.loads(out.stdout.strip().splitlines()[-1]))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--area", default="offices-c")
    parser.add_argument("--seconds", type=float, default=600.0)
    parser.add_argument("--planner", default="classic")
    parser.add_argument("--preset", default="exact")
    parser.add_argument("--baseline", type=Path, default=None,
                        help="another tree's folder, flown alternately with this one")
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--out", default="frontier_clusters", help="name of the JSON written")
    parser.add_argument("--child-tree", type=Path, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child_tree is not None:
        # Every package from that tree (the measuring code above imports none of them).
        sys.path.insert(0, str(args.child_tree))
        print(json.dumps(_child(args.area, args.seconds, args.planner, args.preset)))
        return 0
    sys.path.insert(0, str(HERE))
    from benchmarks.common import checked_baseline, print_table, write_json

    baseline = checked_baseline(args.baseline)
    if args.rounds < 1:
        raise SystemExit(f"--rounds {args.rounds}: at least 1")
    trees = [("this", HERE)] + ([("baseline", baseline)] if baseline else [])
    runs: list[dict[str, Any]] = []
    for round_ in range(args.rounds):
        for label, tree in trees:
            run = _fly(tree, args)
            run["tree"], run["round"] = label, round_ + 1
            runs.append(run)
            print(f"round {round_ + 1}, {label}: {run['total_ms'] / 1e3:.2f} s in "
                  f"{run['calls']} calls", flush=True)
    rows = [[r["tree"], r["round"], r["planner"], r["area"], f"{r['simulated_until']:.0f}",
             r["calls"], f"{r['median_frontier_voxels']:.0f}", f"{r['median_ms']:.2f}",
             f"{r['max_ms']:.2f}", f"{r['total_ms'] / 1e3:.2f}", r["digest"][:12]] for r in runs]
    print_table(f"Frontier clusters per call (preset {args.preset}, seed 0)",
                ["tree", "round", "planner", "area", "until s", "calls", "frontier voxels",
                 "median ms", "max ms", "total s", "digest"], rows)
    summary: dict[str, Any] = {}
    if baseline:
        this = [r for r in runs if r["tree"] == "this"]
        base = [r for r in runs if r["tree"] == "baseline"]
        ratios = [t["total_ms"] / b["total_ms"] for t, b in zip(this, base, strict=True)]
        same = all(t["digest"] == b["digest"] for t, b in zip(this, base, strict=True))
        summary = {"ratios": ratios, "same_clusters": same}
        print("\ntotal clustering time, this / baseline, per round: "
              + ", ".join(f"{r:.3f}" for r in ratios)
              + f"; the same clusters in both trees: {'yes' if same else 'NO'}")
    path = write_json(args.out, {"runs": runs, "seconds": args.seconds, "preset": args.preset,
                                 **summary})
    print(f"\nwrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
