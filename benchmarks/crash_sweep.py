"""Crash sweep: every default planner on every area, counting collisions and safety stops.

    .venv/bin/python benchmarks/crash_sweep.py [--planners classic,fuel] [--areas maze,cafe]
        [--seeds 0] [--seconds S] [--jobs 1] [--recordings DIR]
    .venv/bin/python benchmarks/crash_sweep.py --rescore [--recordings DIR]

By default the planners the leaderboard shows (each registered name's default version) on the
11 built-in areas, seed 0, the default preset, each area's plateau time. `--areas` also takes
imported areas (`flybo areas import`) and `NAME@SEED`, a built-in area generated with another
layout seed (as the held-out split's areas are). Each run is one episode in a process of its
own, `--jobs` at a time. Finished runs are appended to `benchmarks/results/crash_sweep.jsonl` as
they end, and a run already there (same planner id, area, seed, seconds and benchmark version)
is not flown again: a stopped sweep resumes where it stopped.

Each run's recording is kept in `--recordings` (default `benchmarks/results/crash_sweep/`):
`--rescore` recomputes every stored run's coverage from its recording's final map against the
area's current ground truth, so a change of the observable set does not need the flights again.
Per run: how it ended, collisions, safety stops, coverage, F-score, wall time (printed); the
log also keeps the surface's precision, recall and RMSE, peak memory and CPU time.
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from areas.area import Area

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks.common import RESULTS, peak_rss_mib, print_table, write_json

LOG = RESULTS / "crash_sweep.jsonl"
RECORDINGS = RESULTS / "crash_sweep"


def _key(run: dict[str, Any]) -> tuple[str, str, int, float | None, str]:
    return (run["planner"], run["area"], run["seed"], run["seconds"], run["benchmark"])


def _recording_name(planner: str, area: str, seed: int) -> str:
    return f"{area}--{planner}--s{seed}.npz"


def sweep_area(name: str) -> Area:
    """A registered area, or `NAME@SEED`: built-in area NAME generated with layout SEED (a
    layout like the held-out split's, from a seed of the caller's choosing)."""
    from areas import load_area
    from areas.registry import generate_area

    base, sep, seed = name.partition("@")
    if not sep:
        return load_area(name)
    try:
        return generate_area(base, int(seed))
    except ValueError as exc:
        raise SystemExit(f"--areas {name!r}: {exc}") from None


def _run(planner: str, area_name: str, seed: int, seconds: float | None, benchmark: str,
         recordings: str) -> dict[str, Any]:
    from areas import load_ground_truth
    from planners.registry import make, spec
    from sim.config import preset
    from sim.episode import run_episode
    from sim.metrics import timing_summary
    from sim.reference_speed import speed_factor

    area = sweep_area(area_name)
    truth = load_ground_truth(area)
    planner_id = spec(planner).id
    wall0 = time.perf_counter()
    recording = Path(recordings) / _recording_name(planner_id, area_name, seed)
    result = run_episode(area, truth, make(planner_id), preset("default"), seed,
                         planner_name=planner_id, preset_name="default", seconds=seconds,
                         recording_path=recording)
    usage = resource.getrusage(resource.RUSAGE_SELF)
    planning = result.planning_times_ms
    return {
        "planner": planner_id, "area": area_name, "seed": seed, "seconds": seconds,
        "benchmark": benchmark, "status": result.status.value, "reason": result.reason,
        "simulated_until": result.simulated_until, "coverage": result.coverage,
        "fscore": result.surface.fscore, "precision": result.surface.precision,
        "recall": result.surface.recall, "rmse_m": result.surface.rmse_m,
        "collisions": result.collisions,
        "safety_stops": result.safety_stops, "path_length_m": result.path_length_m,
        "wall_s": time.perf_counter() - wall0, "recording": recording.name,
        "iterations": result.iterations,
        "planning_ms_median": timing_summary(planning)["median"] if len(planning) else None,
        # The process flew this run alone (one task per process): its peak and its CPU time
        # (every thread's; what the run costs whatever else the machine runs) are the run's.
        "peak_rss_mib": peak_rss_mib(),
        "cpu_s": usage.ru_utime + usage.ru_stime,
        # The machine's speed as the run's planning charge read it (measured once per process):
        # whole-run CPU times of different days differ by more than it does, so estimates state
        # the factors of the runs they add up (`benchmarks/suite_estimate.py`).
        "speed_factor": speed_factor(),
    }


def _rescore(runs: list[dict[str, Any]], recordings: Path) -> None:
    """Coverage of every run recomputed from its recording against today's ground truth."""
    import numpy as np

    from areas import load_ground_truth
    from sim.recording import Recording

    for run in runs:
        path = recordings / run["recording"]
        if not path.exists():
            continue
        area = sweep_area(run["area"])
        truth = load_ground_truth(area)
        rec = Recording(path)
        known = rec.map_state_at(float("inf")) != 0
        seen = np.count_nonzero(known & truth.observable)
        run["coverage"] = float(seen) / max(1, int(np.count_nonzero(truth.observable)))


def stored_runs(benchmark: str, log: Path = LOG) -> list[dict[str, Any]]:
    """The runs of `benchmark` stored in `log` (none before the first sweep)."""
    if not log.exists():
        return []
    runs = [json.loads(line) for line in log.read_text().splitlines() if line.strip()]
    return [r for r in runs if r["benchmark"] == benchmark]


def _print(runs: list[dict[str, Any]]) -> None:
    runs = sorted(runs, key=lambda r: (r["planner"], r["area"], r["seed"]))
    rows = [[r["planner"], r["area"], r["seed"], r["status"], f"{r['simulated_until']:.0f}",
             r["collisions"], r["safety_stops"], f"{100 * r['coverage']:.1f}",
             f"{100 * r['fscore']:.1f}", f"{r['wall_s']:.0f}", r["reason"][:60]] for r in runs]
    print_table("Crash sweep (default preset)",
                ["planner", "area", "seed", "status", "until s", "collisions", "stops",
                 "coverage %", "F %", "wall s", "reason"], rows)
    crashed = [r for r in runs if r["collisions"] or r["status"] == "crashed"]
    print(f"\n{len(runs)} runs, {len(crashed)} with a collision, "
          f"{sum(r['safety_stops'] for r in runs)} safety stops")
    for r in crashed:
        print(f"  collided: {r['planner']} on {r['area']} seed {r['seed']}: {r['reason']}")


def _default_planners() -> list[str]:
    from planners.registry import planner_names

    return planner_names()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--planners", default=None,
                        help="comma-separated names or ids (default: every registered name)")
    parser.add_argument("--areas", default=None,
                        help="comma-separated areas (default: the built-in ones)")
    parser.add_argument("--seeds", default="0", help="comma-separated seeds")
    parser.add_argument("--seconds", type=float, default=None,
                        help="simulated seconds (default: each area's plateau time)")
    parser.add_argument("--jobs", type=int, default=1)
    parser.add_argument("--recordings", type=Path, default=RECORDINGS)
    parser.add_argument("--rescore", action="store_true",
                        help="fly nothing: rescore the stored runs' coverage and print them")
    parser.add_argument("--benchmark", default=None,
                        help="the benchmark version whose stored runs to rescore (default: "
                             "the tree's); flights of an unchanged planner id and simulator "
                             "stay valid when only the ground truth changed")
    args = parser.parse_args()

    from areas import area_names
    from flybo.versions import benchmark_version
    from planners.registry import spec

    benchmark = benchmark_version()
    done = stored_runs(args.benchmark or benchmark)
    if args.rescore:
        _rescore(done, args.recordings)
        _print(done)
        write_json("crash_sweep", {"benchmark": benchmark, "runs": done})
        return
    planners = [spec(p.strip()).id for p in
                (args.planners.split(",") if args.planners else _default_planners())]
    areas = [a.strip() for a in args.areas.split(",")] if args.areas else area_names()
    for name in areas:
        sweep_area(name)  # an unknown name fails here, before anything flies
    seeds = [int(s) for s in args.seeds.split(",")]
    args.recordings.mkdir(parents=True, exist_ok=True)
    have = {_key(r) for r in done}
    queue = [(p, a, s, args.seconds, benchmark, str(args.recordings))
             for a in areas for p in planners for s in seeds
             if (p, a, s, args.seconds, benchmark) not in have]
    print(f"benchmark {benchmark}: {len(have)} runs stored, {len(queue)} to fly", flush=True)
    runs = list(done)
    LOG.parent.mkdir(parents=True, exist_ok=True)
    with ProcessPoolExecutor(max_workers=args.jobs, max_tasks_per_child=1) as pool:
        futures = [pool.submit(_run, *item) for item in queue]
        for future in as_completed(futures):
            run = future.result()
            runs.append(run)
            with LOG.open("a") as log:
                log.write(json.dumps(run) + "\n")
            print(f"{run['planner']} {run['area']} s{run['seed']}: {run['status']}, "
                  f"collisions {run['collisions']}, coverage {100 * run['coverage']:.1f} %, "
                  f"{run['wall_s']:.0f} s", flush=True)
    wanted = {(p, a, s) for p in planners for a in areas for s in seeds}
    _print([r for r in runs if (r["planner"], r["area"], r["seed"]) in wanted])
    path = write_json("crash_sweep", {"benchmark": benchmark, "runs": runs})
    print(f"\nwrote {path}")


if __name__ == "__main__":
    main()
