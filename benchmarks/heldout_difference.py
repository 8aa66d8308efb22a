"""How different the held-out split's layouts are: for every generated area (family), the share
of occupied voxels that differ between its public scene (seed 0) and held-out seeds, and between
held-out seeds, on the ground-truth voxel grid (`areas.layout_difference`).

    nice -n 10 .venv/bin/python benchmarks/heldout_difference.py [--seeds 3] [--areas a,b]

The held-out seeds are drawn as the service draws them (`server.heldout.heldout_seed`, an HMAC),
here with a fixed benchmark key, so every run measures the same seeds. Prints a table per family
and writes benchmarks/results/heldout_difference.json.
"""

from __future__ import annotations

import argparse
import itertools
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks.common import print_table, write_json

KEY = b"benchmarks/heldout_difference.py"
VERSION = "benchmark"


def measure_family(family: str, n_seeds: int) -> dict[str, Any]:
    """The pairwise differences of `family`'s seed 0 and `n_seeds` held-out seeds."""
    from areas.layout_difference import occupied_difference, occupied_voxels
    from areas.registry import generate_area
    from server.heldout import heldout_seed

    seeds = [0, *(heldout_seed(KEY, VERSION, g, family) for g in range(1, n_seeds + 1))]
    start = time.perf_counter()
    grids = {seed: occupied_voxels(generate_area(family, seed)) for seed in seeds}
    pairs = [{"a": a, "b": b, "difference": round(occupied_difference(grids[a], grids[b]), 4)}
             for a, b in itertools.combinations(seeds, 2)]
    differences = [p["difference"] for p in pairs]
    public = [p["difference"] for p in pairs if p["a"] == 0]
    return {"family": family, "seeds": seeds, "pairs": pairs, "min": min(differences),
            "mean": round(sum(differences) / len(differences), 4), "min_vs_public": min(public),
            "occupied_voxels_seed0": int(grids[0].sum()),
            "seconds": round(time.perf_counter() - start, 1)}


def main() -> None:
    from areas.layout_difference import MIN_LAYOUT_DIFFERENCE
    from areas.registry import _GENERATORS

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3, help="held-out seeds per family")
    parser.add_argument("--areas", default=",".join(sorted(_GENERATORS)),
                        help="comma-separated families (default: every generated area)")
    args = parser.parse_args()
    if args.seeds < 1:
        parser.error("--seeds must be at least 1")
    families = [f.strip() for f in args.areas.split(",") if f.strip()]
    unknown = sorted(set(families) - set(_GENERATORS))
    if unknown:
        parser.error(f"unknown areas: {', '.join(unknown)}")
    results = []
    for family in families:
        result = measure_family(family, args.seeds)
        results.append(result)
        print_table(f"{family}: share of occupied voxels that differ", ["seed a", "seed b",
                    "difference"], [[p["a"], p["b"], f"{p['difference']:.3f}"]
                                    for p in result["pairs"]])
    print_table("Per family", ["family", "min", "mean", "min vs seed 0", "seconds"],
                [[r["family"], f"{r['min']:.3f}", f"{r['mean']:.3f}",
                  f"{r['min_vs_public']:.3f}", r["seconds"]] for r in results])
    overall = min(r["min"] for r in results)
    print(f"\nsmallest difference: {overall:.3f} (tests require {MIN_LAYOUT_DIFFERENCE})")
    path = write_json("heldout_difference", {
        "seeds_per_family": args.seeds, "min_layout_difference_required": MIN_LAYOUT_DIFFERENCE,
        "smallest_difference": overall, "families": results})
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
