"""Simulated seconds per wall second of this build against another, side by side, per area.

    git worktree add /tmp/flybo-old 19f839c        # or: git archive 19f839c | tar -x -C DIR
    nice -n 10 .venv/bin/python benchmarks/sim_speed_ab.py --old /tmp/flybo-old \\
        [--areas all] [--seconds 300] [--planner classic] [--preset default] [--repeats 1]

Each run is a process of its own with one thread per library (`worker.threads`), pinned to one
core when `--core` is given: the build's code is imported from its folder, a 20 s MAZE episode
loads its numba kernels and measures the reference speed, then one episode is timed. The two
builds alternate (old first on even repeats), so that both see the same machine load and their
ratio means something even when absolute times move; the process's CPU time (one thread per
library, so about the wall time on an idle core) moves less with load. Each run reports its
peak resident memory (the whole process: area, ground truth, maps, the warm-up) and a
fingerprint of its result without the fields that measure the machine; with `--charge none`
the flights are repeatable and equal fingerprints show the builds compute the same runs.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from benchmarks.common import print_table, write_json  # noqa: E402
from worker.threads import thread_environment  # noqa: E402

# Measured on the machine, not simulated: left out of the fingerprint.
MACHINE_FIELDS = ("wall_seconds", "frame_costs_ms", "planning_time_ms", "reproducibility")
STAGES = ("render", "occupancy", "tsdf", "physics", "planner", "metrics", "recording", "checks",
          "scoring")


def child(args: argparse.Namespace) -> None:
    """One timed run of the build at `args.root`; prints one JSON line."""
    sys.path.insert(0, str(Path(args.root).resolve()))
    import resource
    import time

    from areas import load_area, load_ground_truth
    from planners.registry import make, spec
    from sim.config import preset
    from sim.episode import run_episode

    if not Path(run_episode.__code__.co_filename).resolve().is_relative_to(
            Path(args.root).resolve()):
        raise SystemExit(f"imported {run_episode.__code__.co_filename}, not from {args.root}")
    config = preset(args.preset)
    if args.charge is not None:
        config = config.model_copy(update={"planning_time_charge": args.charge})
    # Long enough for the planner's and the safety checks' kernels to load (or compile, in a
    # fresh checkout) before the timed run.
    warm = load_area("maze")
    run_episode(warm, load_ground_truth(warm), make(args.planner), config, 0, seconds=20.0)
    area = load_area(args.area)
    truth = load_ground_truth(area)
    started = time.perf_counter()
    cpu0 = time.process_time()
    result = run_episode(area, truth, make(args.planner), config, args.seed,
                         planner_name=spec(args.planner).id, preset_name=args.preset,
                         seconds=args.seconds)
    wall = time.perf_counter() - started
    cpu = time.process_time() - cpu0
    payload = result.to_json()
    canonical = {k: v for k, v in payload.items() if k not in MACHINE_FIELDS}
    text = json.dumps(canonical, sort_keys=True, separators=(",", ":"))
    print(json.dumps({
        "simulated_s": result.simulated_until, "wall_s": wall, "cpu_s": cpu,
        "realtime_factor": result.simulated_until / wall,
        "cpu_realtime_factor": result.simulated_until / cpu if cpu > 0 else None,
        "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        "frame_costs_ms": result.frame_costs_ms, "status": result.status.value,
        "coverage": result.coverage, "iterations": len(result.planning_times_ms),
        "fingerprint": hashlib.sha256(text.encode()).hexdigest(),
    }))


def run_child(root: Path, area: str, args: argparse.Namespace) -> dict[str, Any]:
    command = [sys.executable, str(Path(__file__).resolve()), "--child", "--root", str(root),
               "--area", area, "--seconds", str(args.seconds), "--planner", args.planner,
               "--preset", args.preset, "--seed", str(args.seed)]
    if args.charge is not None:
        command += ["--charge", args.charge]
    if args.core is not None:
        command = ["taskset", "-c", str(args.core), *command]
    done = subprocess.run(command, env=thread_environment(1, os.environ), cwd=root,
                          capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise SystemExit(f"{root} on {area} failed:\n{done.stderr[-3000:]}")
    return dict(json.loads(done.stdout.strip().splitlines()[-1]))


def measure(area: str, builds: dict[str, Path], args: argparse.Namespace) -> dict[str, Any]:
    runs: dict[str, list[dict[str, Any]]] = {name: [] for name in builds}
    for repeat in range(args.repeats):
        order = list(builds) if repeat % 2 == 0 else list(reversed(builds))
        for name in order:
            runs[name].append(run_child(builds[name], area, args))
            last = runs[name][-1]
            print(f"{area} {name}: {last['realtime_factor']:.1f} simulated s per wall s, "
                  f"{last['peak_rss_mib']:.0f} MiB", flush=True)
    row: dict[str, Any] = {"area": area, "runs": runs}
    for name, rs in runs.items():
        row[name] = {
            "realtime_factor": statistics.median(r["realtime_factor"] for r in rs),
            "cpu_realtime_factor": statistics.median(r["cpu_realtime_factor"] for r in rs),
            "peak_rss_mib": max(r["peak_rss_mib"] for r in rs),
            "frame_costs_ms": {k: statistics.median(r["frame_costs_ms"].get(k, 0.0) for r in rs)
                               for k in STAGES},
        }
    # Ratios of runs made one after the other, then their median.
    pairs = zip(runs["new"], runs["old"], strict=True)
    row["speedup"] = statistics.median(n["realtime_factor"] / o["realtime_factor"]
                                       for n, o in pairs)
    row["cpu_speedup"] = statistics.median(
        n["cpu_realtime_factor"] / o["cpu_realtime_factor"]
        for n, o in zip(runs["new"], runs["old"], strict=True))
    row["same_flight"] = all(n["fingerprint"] == o["fingerprint"]
                             for n, o in zip(runs["new"], runs["old"], strict=True))
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--old", type=Path, help="a checkout of the build to compare against")
    parser.add_argument("--new", type=Path, default=ROOT,
                        help="the build to measure (default: this checkout)")
    parser.add_argument("--areas", nargs="+", default=["all"])
    parser.add_argument("--seconds", type=float, default=300.0)
    parser.add_argument("--planner", default="classic")
    parser.add_argument("--preset", default="default")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--charge", choices=("cpu", "wall", "none"), default=None,
                        help="override the preset's planning-time charge")
    parser.add_argument("--core", type=int, default=None, help="pin each run to this core")
    parser.add_argument("--out", default="sim_speed_ab")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--root", help=argparse.SUPPRESS)
    parser.add_argument("--area", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        child(args)
        return
    if args.old is None or not (args.old / "sim" / "episode.py").is_file():
        parser.error("--old must name a checkout of the build to compare against")
    if args.repeats < 1:
        parser.error("--repeats must be at least 1")
    from areas import area_names

    names = area_names() if args.areas == ["all"] else args.areas
    builds = {"old": args.old.resolve(), "new": args.new.resolve()}
    rows: list[dict[str, Any]] = []
    for name in names:
        rows.append(measure(name, builds, args))
        path = save(rows, args)  # after each area, so that a long comparison can be read early
    report(rows, args)
    print(f"\nwrote {path}")


def save(rows: list[dict[str, Any]], args: argparse.Namespace) -> Path:
    return write_json(args.out, {
        "command": "python benchmarks/sim_speed_ab.py " + " ".join(sys.argv[1:]),
        "old": str(args.old), "new": str(args.new), "planner": args.planner,
        "preset": args.preset, "seconds": args.seconds, "seed": args.seed,
        "charge": args.charge, "areas": rows,
    })


def report(rows: list[dict[str, Any]], args: argparse.Namespace) -> None:
    print_table(
        f"{args.planner}, preset {args.preset}, {args.seconds:g} simulated s, seed {args.seed}, "
        f"{args.repeats} run(s) per build, old = {args.old}",
        ["area", "old sim s / wall s", "new", "new / old", "old sim s / CPU s", "new",
         "new / old", "old MiB", "new MiB", "same flight"],
        [[r["area"], f"{r['old']['realtime_factor']:.1f}", f"{r['new']['realtime_factor']:.1f}",
          f"{r['speedup']:.2f}", f"{r['old']['cpu_realtime_factor']:.1f}",
          f"{r['new']['cpu_realtime_factor']:.1f}", f"{r['cpu_speedup']:.2f}",
          f"{r['old']['peak_rss_mib']:.0f}",
          f"{r['new']['peak_rss_mib']:.0f}", "yes" if r["same_flight"] else "no"]
         for r in rows],
    )
    print_table(
        "per fused frame, ms (new; old in brackets)", ["area", *STAGES],
        [[r["area"], *(f"{r['new']['frame_costs_ms'][k]:.2f} ({r['old']['frame_costs_ms'][k]:.2f})"
                       for k in STAGES)] for r in rows],
    )


if __name__ == "__main__":
    main()
