"""Do the public and the held-out split rank the paper's seven planners alike?

    .venv/bin/python benchmarks/split_ranks.py [--log benchmarks/results/crash_sweep.jsonl] \
        [--published docs/RESULTS.md] [--benchmark V]

The held-out cells are a crash sweep's runs (`benchmarks/crash_sweep.py`) on `FAMILY@SEED`
areas: a built-in area's generator run with another layout seed, as the service builds its
held-out areas (`server/heldout.py`). The public cells are the sweep's runs on the 11 built-in
areas (seed 0 layouts) where the log has them, and otherwise the runs published in
`--published` (the crash-sweep tables of `docs/RESULTS.md`): per planner family and area, the
row of the family's default version (what its bare name stands for), else of its newest version
that has one, the first such row when several tables hold it. Per planner the default version
is used on the held-out split.

Both splits are scored as the leaderboard scores a split: relative coverage (explored observable
volume over the best planner's on the area) ranked per area, the ranks averaged over the areas;
every coverage is taken to the published tables' 0.1 %, so that ties count alike on both.
Prints per split the average coverage ranks, their Kendall tau, each planner's mean coverage on
both and the gap between them (public minus held-out), and each held-out run's end,
collisions and safety stops. Writes `benchmarks/results/split_ranks.json`.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks.common import print_table, write_json
from benchmarks.paper_findings import family, our_cells, tau
from benchmarks.paper_reference import AREAS, PLANNERS, average_ranks

ROOT = Path(__file__).resolve().parent.parent
# A crash-sweep row: | `id` | AREA | ended | coverage % | F-score % | collisions | stops | ...
_ROW = re.compile(r"^\| `(?P<planner>[a-z0-9-]+)` \| (?P<area>[A-Za-z0-9@-]+) \| (?P<ended>[^|]*)"
                  r"\| (?P<coverage>[0-9.]+) \| (?P<fscore>[0-9.]+) \| (?P<collisions>\d+) "
                  r"\| (?P<stops>\d+) \|")


def published_runs(path: Path) -> list[dict[str, Any]]:
    """The crash-sweep rows of a results page, as runs (coverage and F-score as fractions)."""
    runs = []
    for line in path.read_text().splitlines():
        match = _ROW.match(line)
        if match:
            runs.append({"planner": match["planner"], "area": match["area"].lower(),
                         "status": match["ended"].strip(),
                         "coverage": float(match["coverage"]) / 100.0,
                         "fscore": float(match["fscore"]) / 100.0,
                         "collisions": int(match["collisions"]),
                         "safety_stops": int(match["stops"]), "source": str(path)})
    return runs


def _version(planner_id: str) -> int:
    from planners.registry import parse_id

    return parse_id(planner_id)[1] or 0


def public_runs(logged: list[dict[str, Any]], published: list[dict[str, Any]]
                ) -> list[dict[str, Any]]:
    """One run per paper family and built-in area: the log's run of the family's default
    version (what its bare name stands for, as on the held-out side), else of its newest
    version; failing both, the published one's (the first row of that version)."""
    from planners.registry import spec

    default = {spec(name).id for name in PLANNERS}

    def preference(planner_id: str) -> tuple[bool, int]:
        return planner_id in default, _version(planner_id)

    chosen: dict[tuple[str, str], dict[str, Any]] = {}
    for source in (logged, published):
        for run in source:
            if run["area"] not in AREAS or family(run["planner"]) not in PLANNERS:
                continue
            key = (family(run["planner"]), run["area"])
            have = chosen.get(key)
            if have is None or (have.get("source") == run.get("source")
                                and preference(run["planner"]) > preference(have["planner"])):
                chosen[key] = run
    return list(chosen.values())


def heldout_runs(logged: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The log's runs on `FAMILY@SEED` areas by each paper family's default version,
    with `area` the family and `layout` the whole name."""
    from planners.registry import spec

    latest = {spec(name).id for name in PLANNERS}
    runs = []
    for run in logged:
        base, sep, _ = run["area"].partition("@")
        if sep and base in AREAS and run["planner"] in latest:
            runs.append({**run, "area": base, "layout": run["area"]})
    return runs


def _published_precision(runs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Coverage to the published tables' precision (0.1 %), so that both splits tie alike."""
    return [{k: v for k, v in {**r, "coverage": round(r["coverage"], 3)}.items()
             if k != "explored_observable_m3"} for r in runs]


def compare(public: list[dict[str, Any]], heldout: list[dict[str, Any]]) -> dict[str, Any]:
    """Average coverage ranks of both splits over the families both have, and their tau."""
    cells = {"public": our_cells(_published_precision(public)),
             "heldout": our_cells(_published_precision(heldout))}
    planners = sorted(set(cells["public"]) & set(cells["heldout"]), key=PLANNERS.index)
    areas = sorted({a for by_area in cells["heldout"].values() for a in by_area},
                   key=AREAS.index)
    ranks: dict[str, dict[str, float]] = {}
    mean: dict[str, dict[str, float]] = {}
    for split, by_planner in cells.items():
        common = {p: {a: by_planner[p][a] for a in areas if a in by_planner[p]}
                  for p in planners}
        ranks[split] = average_ranks(common, "relative")
        mean[split] = {p: float(np.mean([c["coverage"] for c in common[p].values()]))
                       for p in planners}
    missing = sorted(f"{p} {a} ({split})" for split in cells for p in planners for a in areas
                     if a not in cells[split][p])
    return {"planners": planners, "areas": areas, "missing": missing,
            "average_coverage_rank": ranks, "mean_coverage": mean,
            "gap_pp": {p: 100.0 * (mean["public"][p] - mean["heldout"][p]) for p in planners},
            "kendall_tau": tau(ranks["public"], ranks["heldout"])}


def main() -> None:
    from benchmarks.crash_sweep import LOG, stored_runs
    from flybo.versions import benchmark_version

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--log", type=Path, default=LOG, help="a crash sweep's log")
    parser.add_argument("--published", type=Path, default=ROOT / "docs" / "RESULTS.md",
                        help="a results page whose crash-sweep tables fill public cells")
    parser.add_argument("--benchmark", default=None,
                        help="the benchmark version of the logged runs (default: the tree's)")
    args = parser.parse_args()
    version = args.benchmark or benchmark_version()
    if not args.log.exists():
        raise SystemExit(f"--log {args.log}: no such file (run benchmarks/crash_sweep.py)")
    logged = stored_runs(version, args.log)
    heldout = heldout_runs(logged)
    if not heldout:
        raise SystemExit(f"{args.log}: no run of benchmark {version} on a FAMILY@SEED area "
                         "by a paper planner's default version")
    public = public_runs(logged, published_runs(args.published)
                         if args.published.exists() else [])
    summary = compare(public, heldout)
    rows = [[p, f"{summary['average_coverage_rank']['public'][p]:.2f}",
             f"{summary['average_coverage_rank']['heldout'][p]:.2f}",
             f"{100 * summary['mean_coverage']['public'][p]:.1f}",
             f"{100 * summary['mean_coverage']['heldout'][p]:.1f}",
             f"{summary['gap_pp'][p]:+.1f}"] for p in summary["planners"]]
    print_table(f"Public and held-out split over {len(summary['areas'])} families",
                ["planner", "public rank", "held-out rank", "public coverage %",
                 "held-out coverage %", "gap pp"], rows)
    value = summary["kendall_tau"]
    print(f"\nKendall tau of the average coverage ranks, public against held-out: "
          f"{'-' if value is None else f'{value:.2f}'}")
    if summary["missing"]:
        print("missing cells: " + ", ".join(summary["missing"]))
    print_table("Held-out runs", ["planner", "layout", "ended", "coverage %", "collisions",
                                  "safety stops"],
                [[r["planner"], r["layout"], r.get("reason") or r["status"],
                  f"{100 * r['coverage']:.1f}", r["collisions"], r["safety_stops"]]
                 for r in sorted(heldout, key=lambda r: (AREAS.index(r["area"]),
                                                          PLANNERS.index(family(r["planner"]))))])
    path = write_json("split_ranks", {
        "command": "python benchmarks/split_ranks.py " + " ".join(sys.argv[1:]),
        "benchmark": version, "public_runs": public, "heldout_runs": heldout, **summary})
    print(f"\nwrote {path}")


if __name__ == "__main__":
    main()
