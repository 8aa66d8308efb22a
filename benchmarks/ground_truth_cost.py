"""What an area's ground truth costs to compute, stage by stage, optionally beside another tree.

    taskset -c 0 .venv/bin/python benchmarks/ground_truth_cost.py [--areas maze,facility-c]
        [--baseline DIR] [--repeat 1]

For each area (the mesh generated first, not timed) one fresh process per tree times:
`blocked_voxels` (Open3D's distance to the mesh at voxel centres), one pass over the 2 cm
surface samples (`_sample_chunks`: drawing them and finding the voxels either side) and the
whole `compute_ground_truth` (blocked voxels, observability, two sample passes, the surface
layer), each the fastest of ``--repeat``. With ``--baseline DIR`` (a `git archive` of another
commit, unpacked) every area is computed by both trees, alternately, and the results are
compared: a digest of the observable voxels, the surface cloud and the volumes.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent.parent


def _child(area_name: str, repeat: int) -> dict[str, Any]:
    import numpy as np

    import flybo  # noqa: F401  pins the CPU kernels first
    from areas import ground_truth as gt
    from areas.registry import load_area

    area = load_area(area_name)
    vertices = np.asarray(area.vertices, dtype=np.float64)
    triangles = np.asarray(area.triangles, dtype=np.int64)
    seed = int(area.content_hash[:16], 16)

    def best(fn: Any) -> tuple[float, Any]:
        times, out = [], None
        for _ in range(repeat):
            start = time.perf_counter()
            out = fn()
            times.append(time.perf_counter() - start)
        return min(times), out

    def one_pass() -> int:
        return sum(len(chunk[0]) for chunk in gt._sample_chunks(
            area, vertices, triangles, gt.DEFAULT_SAMPLE_SPACING, seed))

    # One untimed pass compiles what the tree compiles (numba's cache may be cold).
    one_pass()
    blocked_s, _ = best(lambda: gt.blocked_voxels(area))
    samples_s, samples = best(one_pass)
    total_s, truth = best(lambda: gt.compute_ground_truth(area))
    digest = hashlib.sha256()
    digest.update(np.packbits(truth.observable.ravel()).tobytes())
    digest.update(np.ascontiguousarray(truth.surface.plain).tobytes())
    digest.update(np.array([truth.free_volume_m3, truth.reachable_volume_m3,
                            truth.observable_free_m3]).tobytes())
    return {"area": area_name, "blocked_s": blocked_s, "sample_pass_s": samples_s,
            "total_s": total_s, "samples": samples, "faces": len(triangles),
            "perceivable": len(truth.surface.plain), "digest": digest.hexdigest()[:16]}


def _measure(tree: Path, area: str, repeat: int) -> dict[str, Any]:
    cmd = [sys.executable, str(HERE / "benchmarks" / "ground_truth_cost.py"),
           "--child-tree", str(tree), "--areas", area, "--repeat", str(repeat)]
    out = subprocess.run(cmd, cwd=tree, check=True, capture_output=True, text=True)
    return dict(json.loads(out.stdout.strip().splitlines()[-1]))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--areas", default="maze,warehouse,powerplant,facility-c",
                        help="comma-separated built-in areas, or 'all'")
    parser.add_argument("--baseline", type=Path, default=None,
                        help="another tree's folder, measured beside this one")
    parser.add_argument("--repeat", type=int, default=1, help="runs of each stage, fastest kept")
    parser.add_argument("--child-tree", type=Path, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.repeat < 1:
        raise SystemExit(f"--repeat {args.repeat}: at least 1")
    if args.child_tree is not None:
        sys.path.insert(0, str(args.child_tree))
        print(json.dumps(_child(args.areas, args.repeat)))
        return 0
    sys.path.insert(0, str(HERE))
    from areas import area_names
    from benchmarks.common import checked_baseline, print_table, write_json

    baseline = checked_baseline(args.baseline, "areas")
    names = list(area_names()) if args.areas == "all" else [
        a.strip() for a in args.areas.split(",")]
    unknown = sorted(set(names) - set(area_names()))
    if unknown:
        raise SystemExit(f"unknown areas: {', '.join(unknown)} (known: "
                         f"{', '.join(area_names())})")
    trees = [("this", HERE)] + ([("baseline", baseline)] if baseline else [])
    rows, results = [], []
    for name in names:
        measured = {label: _measure(tree, name, args.repeat) for label, tree in trees}
        for label, r in measured.items():
            r["tree"] = label
            results.append(r)
            rows.append([name, label, f"{r['faces']:,}", f"{r['samples']:,}",
                         f"{r['blocked_s']:.2f}", f"{r['sample_pass_s']:.2f}",
                         f"{r['total_s']:.2f}", r["digest"]])
        if args.baseline:
            this, base = measured["this"], measured["baseline"]
            rows.append([name, "ratio", "", "", f"{this['blocked_s'] / base['blocked_s']:.2f}",
                         f"{this['sample_pass_s'] / base['sample_pass_s']:.2f}",
                         f"{this['total_s'] / base['total_s']:.2f}",
                         "identical" if this["digest"] == base["digest"] else "DIFFERENT"])
        print(f"{name} done", flush=True)
    print_table("Ground truth per area (seconds, fastest of --repeat)",
                ["area", "tree", "faces", "samples", "blocked voxels", "one sample pass",
                 "whole", "digest"], rows)
    path = write_json("ground_truth_cost", {"results": results, "repeat": args.repeat})
    print(f"\nwrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
