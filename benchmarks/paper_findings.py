"""Our results beside the FLYBO paper's Tables 2 and 3, and its findings held or not.

    .venv/bin/python benchmarks/paper_findings.py [--planners classic rapid ...] \
        [--areas maze warehouse ...] [--runs 5 | --seeds 0 3] [--preset default] \
        [--seconds S] [--jobs 2] [--name NAME] [--load A.json B.json] [--bootstrap 1000]
    .venv/bin/python benchmarks/paper_findings.py --sweep benchmarks/results/crash_sweep.jsonl \
        [benchmarks/records/crash_sweep-....jsonl ...]

Flies every planner x area x seed to the area's plateau time (or `--seconds`), `--jobs` runs at
a time in separate processes, then prints per area the relative coverage (the leaderboard's:
explored observable volume over the best planner's mean on that area) and the F-score beside the
paper's, the Kendall tau between our average ranks and the paper's (both ranked over the planners
and areas flown here), how far each tau moves when every cell's runs are drawn again with
replacement (`--bootstrap`, where cells hold several seeds), and each finding of the paper's
sections 4.1-4.3 marked held, not held or not measured. `--load` reads the runs of earlier JSONs
instead of flying (subsets flown apart are compared together); `--sweep` reads crash sweeps'
runs (a cell's seeds averaged; RMSE and recall where the sweep logged them), those on
`--areas` and `--seeds` where given; given both, the loaded runs of a planner and area replace
the sweep's (the large areas flown with another camera, say). Writes
`benchmarks/results/paper_findings.json` (or `--name`).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import kendalltau

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks.common import print_table, write_json
from benchmarks.paper_reference import (
    AREAS,
    PAPER_TABLE2,
    PAPER_TABLE3_FSCORE,
    PAPER_TABLE3_RMSE,
    PLANNERS,
    Cells,
    average_ranks,
    findings,
)
from sim.metrics import relative_coverage


def fly(task: tuple[str, str, int, str, float | None]) -> dict[str, Any]:
    """One run (in a worker process): its scores."""
    from areas import load_area, load_ground_truth
    from planners.registry import make, spec
    from sim.config import preset
    from sim.episode import run_episode

    planner_id, area_name, seed, preset_name, seconds = task
    area = load_area(area_name)
    pid = spec(planner_id).id
    result = run_episode(area, load_ground_truth(area), make(pid), preset(preset_name), seed,
                         planner_name=pid, preset_name=preset_name, seconds=seconds)
    observable = result.metrics.get("explored_observable_m3")
    return {"planner": pid, "area": area_name, "seed": seed, "status": result.status.value,
            "reason": result.reason, "coverage": result.coverage,
            "explored_observable_m3": observable if observable is not None
            else result.explored_volume_m3,
            "fscore": result.surface.fscore, "rmse_m": result.surface.rmse_m,
            "recall": result.surface.recall, "iterations": result.iterations,
            "planning_ms_median": float(np.median(result.planning_times_ms))
            if len(result.planning_times_ms) else None,
            "simulated_until": result.simulated_until}


def family(planner_id: str) -> str:
    from planners.registry import parse_id

    return parse_id(planner_id)[0]


def _explored(run: dict[str, Any]) -> float:
    """What relative coverage divides: the explored observable volume, or, for a crash-sweep
    run that does not store it, the coverage (the same volume over the area's observable
    volume, so the ratios within an area are the same)."""
    return float(run["explored_observable_m3"] if "explored_observable_m3" in run
                 else run["coverage"])


def our_cells(runs: list[dict[str, Any]]) -> Cells:
    """Means per planner family and area; relative coverage as the leaderboard's. A score
    that some run of a cell lacks (crash sweeps logged before 2026-12-06 store no RMSE or
    recall) is left out."""
    groups: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for run in runs:
        groups.setdefault((family(run["planner"]), run["area"]), []).append(run)
    best: dict[str, float] = {}
    for (_, area), members in groups.items():
        mean = float(np.mean([_explored(m) for m in members]))
        best[area] = max(best.get(area, 0.0), mean)
    cells: Cells = {}
    for (name, area), members in groups.items():
        coverages = [m["coverage"] for m in members]
        cell = {
            "coverage": float(np.mean(coverages)),
            "coverage_min": float(min(coverages)), "coverage_max": float(max(coverages)),
            "runs": len(members),
            "relative": float(np.mean([relative_coverage(_explored(m), best[area])
                                       for m in members])),
        }
        for key, field in (("fscore", "fscore"), ("rmse", "rmse_m"), ("recall", "recall")):
            if all(m.get(field) is not None for m in members):
                cell[key] = float(np.mean([m[field] for m in members]))
        cells.setdefault(name, {})[area] = cell
    return cells


def sweep_runs(paths: Path | Sequence[Path], benchmark: str | None) -> list[dict[str, Any]]:
    """The runs of one or more crash sweeps' logs (`benchmarks/crash_sweep.py`) that this
    comparison can use: benchmark `benchmark` (default: this tree's), the paper's areas, and per
    planner family of the paper the version its name resolves to now (the leaderboard's
    default). A run found in several logs (same planner, area, seed and seconds) counts once."""
    from benchmarks.crash_sweep import stored_runs
    from flybo.versions import benchmark_version
    from planners.registry import UnknownPlannerError, spec

    logs = [paths] if isinstance(paths, Path) else list(paths)
    wanted = benchmark or benchmark_version()
    latest = {}
    for name in PLANNERS:
        try:
            latest[name] = spec(name).id
        except UnknownPlannerError:
            continue
    chosen: dict[tuple[Any, ...], dict[str, Any]] = {}
    for log in logs:
        for r in stored_runs(wanted, log):
            if r["area"] in AREAS and r["planner"] == latest.get(family(r["planner"])):
                chosen.setdefault((r["planner"], r["area"], r["seed"], r.get("seconds")), r)
    if not chosen:
        raise SystemExit(f"{', '.join(map(str, logs))}: no run of benchmark {wanted} by "
                         f"{', '.join(latest.values())} on the paper's areas")
    return list(chosen.values())


def paper_cells(planners: list[str], areas: list[str]) -> Cells:
    return {p: {a: {"relative": PAPER_TABLE2[p][AREAS.index(a)],
                    "fscore": PAPER_TABLE3_FSCORE[p][AREAS.index(a)],
                    "rmse": PAPER_TABLE3_RMSE[p][AREAS.index(a)]} for a in areas}
            for p in planners}


def tau(ours: dict[str, float], paper: dict[str, float]) -> float | None:
    """Kendall tau (tau-b) between two average-rank orders over their common planners."""
    common = sorted(set(ours) & set(paper))
    if len(common) < 2:
        return None
    value = float(kendalltau([ours[p] for p in common], [paper[p] for p in common]).statistic)
    return None if np.isnan(value) else value


def compare(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """Our cells and the paper's over the same planners and areas, ranks, taus, findings."""
    ours = our_cells(runs)
    unknown = sorted(set(ours) - set(PLANNERS))
    flown = sorted(ours, key=lambda p: PLANNERS.index(p) if p in PLANNERS else 99)
    areas = [a for a in AREAS if any(a in ours[p] for p in ours)]
    paper = paper_cells([p for p in flown if p in PLANNERS], areas)
    ranked = {}
    for key, lower in (("relative", False), ("fscore", False), ("rmse", True)):
        ranked[key] = {"ours": average_ranks(ours, key, lower),
                       "paper": average_ranks(paper, key, lower)}
    return {"planners": flown, "areas": areas, "not_in_paper": unknown,
            "ours": ours, "paper": paper, "average_ranks": ranked,
            "kendall_tau": {k: tau(v["ours"], v["paper"]) for k, v in ranked.items()},
            "findings": findings(ours)}


def tau_intervals(runs: list[dict[str, Any]], replicates: int,
                  rng: np.random.Generator) -> dict[str, dict[str, float]]:
    """How far the Kendall taus of `compare` move with the seeds: the runs of each cell
    (planner family x area) are drawn again with replacement, as many as it has, `replicates`
    times; per score, the 5th and 95th percentiles of the taus and the share of draws at or
    above the issue's targets (coverage 0.6, F-score 0.5). Cells of one run each, or scores a
    draw cannot rank, give no interval."""
    groups: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for run in runs:
        groups.setdefault((family(run["planner"]), run["area"]), []).append(run)
    if all(len(m) < 2 for m in groups.values()):
        return {}
    reference = compare(runs)
    paper = reference["average_ranks"]
    taus: dict[str, list[float]] = {"relative": [], "fscore": []}
    for _ in range(replicates):
        drawn = [m[i] for m in groups.values() for i in rng.integers(0, len(m), len(m))]
        ours = our_cells(drawn)
        for key in taus:
            value = tau(average_ranks(ours, key, False), paper[key]["paper"])
            if value is not None:
                taus[key].append(value)
    out = {}
    for key, values in taus.items():
        if values:
            target = TAU_TARGETS[key]
            out[key] = {"p5": float(np.percentile(values, 5)),
                        "p95": float(np.percentile(values, 95)),
                        "share_at_target": float(np.mean(np.array(values) >= target)),
                        "target": target, "replicates": len(values)}
    return out


# The Kendall taus the benchmark's faithfulness is held to (coverage ranks, F-score ranks).
TAU_TARGETS = {"relative": 0.6, "fscore": 0.5}


def _fmt(value: float | None, digits: int = 4) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def report(summary: dict[str, Any]) -> None:
    ours, paper, areas = summary["ours"], summary["paper"], summary["areas"]
    for key, title in (("relative", "Relative coverage (Table 2)"),
                       ("fscore", "F-score (Table 3)")):
        rows = []
        for p in summary["planners"]:
            cells = [f"{_fmt(ours[p].get(a, {}).get(key))} / "
                     f"{_fmt(paper.get(p, {}).get(a, {}).get(key))}" for a in areas]
            r = summary["average_ranks"][key]
            rows.append([p, *cells, f"{_fmt(r['ours'].get(p), 2)} / "
                         f"{_fmt(r['paper'].get(p), 2)}"])
        print_table(f"{title}: ours / the paper's", ["planner", *areas, "avg rank"], rows)
    rows = []
    for p in summary["planners"]:
        cells = []
        for a in areas:
            c = ours[p].get(a)
            cells.append("-" if c is None else
                         f"{100 * c['coverage']:.1f} ({100 * c['coverage_min']:.1f}-"
                         f"{100 * c['coverage_max']:.1f}, {c['runs']})")
        rows.append([p, *cells])
    print_table("Coverage of the observable volume, %: mean (least-most, runs)",
                ["planner", *areas], rows)
    taus = summary["kendall_tau"]
    print(f"\nKendall tau of average ranks, ours against the paper's over the same planners and "
          f"areas: coverage {_fmt(taus['relative'], 2)}, F-score {_fmt(taus['fscore'], 2)}, "
          f"RMSE {_fmt(taus['rmse'], 2)}")
    for key, name in (("relative", "coverage"), ("fscore", "F-score")):
        spread = summary.get("tau_intervals", {}).get(key)
        if spread:
            print(f"  {name}: 5-95 % of {spread['replicates']} draws of the seeds per cell "
                  f"{spread['p5']:.2f} to {spread['p95']:.2f}; at or above "
                  f"{spread['target']:.1f} in {100 * spread['share_at_target']:.0f} %")
    print_table("The paper's findings (sections 4.1-4.3)", ["section", "status", "finding"],
                [[f["section"], f["status"], f["finding"]] for f in summary["findings"]])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--planners", nargs="+", default=list(PLANNERS),
                        help="ids or names (a name is its default version), one per family")
    parser.add_argument("--areas", nargs="+", default=list(AREAS),
                        help="the areas to fly, or to take from --sweep")
    parser.add_argument("--runs", type=int, default=1, help="seeds 0 .. runs-1")
    parser.add_argument("--seeds", type=int, nargs="+", default=None,
                        help="the seeds to fly, or to take from --sweep (default: all there)")
    parser.add_argument("--preset", default="default")
    parser.add_argument("--seconds", type=float, default=None,
                        help="simulated seconds (default: each area's plateau time)")
    parser.add_argument("--jobs", type=int, default=1, help="runs flown at a time")
    parser.add_argument("--load", type=Path, nargs="+", default=None,
                        help="take the runs from these JSONs (of this script, or of "
                             "sensor_range.py) or JSON-lines records instead of flying; with "
                             "--sweep, in place of the sweep's runs of the same planner and area")
    parser.add_argument("--sweep", type=Path, nargs="+", default=None,
                        help="take the runs from crash sweeps' logs (crash_sweep.jsonl, or "
                             "kept ones under benchmarks/records): coverage and F-score only, "
                             "no RMSE")
    parser.add_argument("--benchmark", default=None,
                        help="with --sweep: the benchmark version whose runs to take "
                             "(default: this tree's)")
    parser.add_argument("--bootstrap", type=int, default=1000,
                        help="draws of each cell's runs for the taus' spread (0: none)")
    parser.add_argument("--name", default="paper_findings",
                        help="the JSON's name under benchmarks/results/")
    args = parser.parse_args()
    runs = gathered_runs(args) if args.load or args.sweep else fly_all(args)
    summary = compare(runs)
    if args.bootstrap > 0:
        # A fixed seed: the same runs give the same intervals.
        summary["tau_intervals"] = tau_intervals(runs, args.bootstrap, np.random.default_rng(0))
    report(summary)
    path = write_json(args.name, {
        "command": "python benchmarks/paper_findings.py " + " ".join(sys.argv[1:]),
        "preset": args.preset, "runs": runs, **summary})
    print(f"wrote {path}")


def loaded_runs(path: Path) -> list[dict[str, Any]]:
    """The runs of a JSON with a "runs" list (this script's, `sensor_range.py`'s), or of a
    JSON-lines file with one run per line (the records under `benchmarks/records/`)."""
    text = path.read_text()
    if path.suffix == ".jsonl":
        return [json.loads(line) for line in text.splitlines() if line.strip()]
    runs: list[dict[str, Any]] = json.loads(text)["runs"]
    return runs


def _tree_version() -> str:
    from flybo.versions import benchmark_version

    return benchmark_version()


def gathered_runs(args: argparse.Namespace) -> list[dict[str, Any]]:
    """The runs of `--load` and `--sweep` on `--areas` and `--seeds`. Given both, the loaded
    runs of a planner and area replace the sweep's of that planner and area, so that a cell's
    mean never mixes runs flown under different settings (a `--load` record may hold runs with
    another camera, `benchmarks/sensor_range.py`); the cells replaced are printed."""
    def wanted(run: dict[str, Any]) -> bool:
        return run["area"] in args.areas and (args.seeds is None or run["seed"] in args.seeds)

    loaded = [r for path in args.load or [] for r in loaded_runs(path) if wanted(r)]
    version = args.benchmark or _tree_version()
    other = sorted({r["benchmark"] for r in loaded if r.get("benchmark", version) != version})
    if other:
        raise SystemExit(f"--load holds runs of benchmark {', '.join(other)}, not {version} "
                         "(--benchmark names the version to compare)")
    swept = [r for r in sweep_runs(args.sweep, args.benchmark) if wanted(r)] if args.sweep else []
    replaced = ({(family(r["planner"]), r["area"]) for r in loaded}
                & {(family(r["planner"]), r["area"]) for r in swept})
    if replaced:
        print("runs from --load in place of the sweep's: "
              + ", ".join(f"{p} on {a}" for p, a in sorted(replaced)), flush=True)
        swept = [r for r in swept if (family(r["planner"]), r["area"]) not in replaced]
    if not loaded and not swept:
        raise SystemExit("no run of the sweeps or loaded JSONs on the areas and seeds asked for")
    return loaded + swept


def fly_all(args: argparse.Namespace) -> list[dict[str, Any]]:
    from planners.registry import UnknownPlannerError, spec

    try:
        ids = [spec(p).id for p in args.planners]
    except UnknownPlannerError as exc:
        raise SystemExit(str(exc)) from None
    families = [family(i) for i in ids]
    if len(set(families)) != len(families):
        raise SystemExit(f"one version per planner family, please: {' '.join(ids)}")
    unknown = sorted(set(args.areas) - set(AREAS))
    if unknown:
        raise SystemExit(f"not an area of the paper: {' '.join(unknown)} "
                         f"(known: {' '.join(AREAS)})")
    seeds = args.seeds if args.seeds is not None else list(range(args.runs))
    tasks = [(i, a, s, args.preset, args.seconds) for a in args.areas for s in seeds
             for i in ids]
    runs = []
    with ProcessPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        for run in pool.map(fly, tasks):
            print(f"{run['area']} seed {run['seed']} {run['planner']}: coverage "
                  f"{run['coverage']:.3f}, F-score {run['fscore']:.3f}, {run['reason']}",
                  flush=True)
            runs.append(run)
    return runs


if __name__ == "__main__":
    main()
