"""ESM versions side by side: coverage and planning time per iteration, area by area.

    nice -n 10 .venv/bin/python benchmarks/esm_versions.py \
        [--planners esm-ipp-v2 esm-ipp-v1] [--areas warehouse powerplant] [--seeds 0] \
        [--preset default] [--seconds S]

One run per planner, area and seed, one after the other in this process, to the area's plateau
time (or `--seconds`). Planning time per `plan` call is given twice: as the process's CPU time
(what the default preset charges to the simulated clock, before the machine's speed factor, and
what a busy machine does not inflate) and as wall time (the run's `planning_time_ms`). The tree's
size at the last call shows whether it stays bounded. The simulated seconds charged are split
into those of calls made at rest (the vehicle hovers) and of calls made in flight (it flies on).
The explored volume is given at each quarter of the run, with the first times it reached 95 and
99 % of the run's final explored volume. `docs/planners/esm.md` holds the figures this script gave.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from areas import load_area, load_ground_truth
from benchmarks.common import print_table, write_json
from planners.registry import make, spec
from sim.config import preset
from sim.episode import run_episode
from sim.interface import Observation, Plan, PlanOutcome
from sim.result import EpisodeResult


def _timed(planner: Any) -> list[tuple[float, float, int, bool]]:
    """Wrap `planner.plan` to log (time, CPU ms, tree nodes, asked in flight) per call."""
    log: list[tuple[float, float, int, bool]] = []
    inner = planner.plan

    def plan(obs: Observation) -> Plan:
        t0 = time.process_time()
        result = inner(obs)
        log.append((obs.time, 1000.0 * (time.process_time() - t0),
                    int(result.info.get("nodes", 0)),
                    obs.last_outcome == PlanOutcome.FLYING))
        return result

    planner.plan = plan
    return log


def coverage_course(result: EpisodeResult) -> dict[str, Any]:
    """The explored volume (m³) at each quarter of the run and the first simulated times it
    reached 95 and 99 % of the run's final explored volume."""
    times, volume = result.volume_times, result.volume_m3
    if len(times) == 0 or volume[-1] <= 0:
        return {"quarters": [], "t95_s": None, "t99_s": None}
    share = volume / volume[-1]
    quarters = [float(np.interp(q * result.sim_seconds, times, volume))
                for q in (0.25, 0.5, 0.75)]

    def first(level: float) -> float | None:
        reached = np.flatnonzero(share >= level)
        return float(times[reached[0]]) if len(reached) else None

    return {"quarters": quarters, "t95_s": first(0.95), "t99_s": first(0.99)}


def fly(planner_id: str, area_name: str, seed: int, preset_name: str,
        seconds: float | None) -> dict[str, Any]:
    area = load_area(area_name)
    pid = spec(planner_id).id
    planner = make(pid)
    log = _timed(planner)
    t0 = time.perf_counter()
    result = run_episode(area, load_ground_truth(area), planner, preset(preset_name), seed,
                         planner_name=pid, preset_name=preset_name, seconds=seconds)
    cpu = np.array([ms for _, ms, _, _ in log]) if log else np.zeros(1)
    half = len(log) // 2
    charged = np.asarray(result.charged_s, dtype=np.float64)
    in_flight = np.array([f for *_, f in log], dtype=bool)
    split = len(charged) == len(in_flight)  # one charge per logged call
    return {
        "planner": pid, "area": area_name, "seed": seed, "coverage": result.coverage,
        "status": result.status.value, "reason": result.reason,
        "ended_at_s": result.simulated_until, "iterations": result.iterations,
        "path_length_m": result.path_length_m,
        "cpu_ms_median": float(np.median(cpu)), "cpu_ms_p90": float(np.percentile(cpu, 90)),
        # Independence of the explored area's size: the first half of the calls against the
        # second, when the explored volume and the tree are larger.
        "cpu_ms_median_first_half": float(np.median(cpu[:half])) if half else None,
        "cpu_ms_median_second_half": float(np.median(cpu[half:])) if half else None,
        "wall_ms_median": float(np.median(result.planning_times_ms))
        if len(result.planning_times_ms) else None,
        "nodes_last": log[-1][2] if log else 0,
        "nodes_max": max((n for _, _, n, _ in log), default=0),
        "calls_in_flight": int(np.count_nonzero(in_flight)),
        "charged_at_rest_s": float(charged[~in_flight].sum()) if split else None,
        "charged_in_flight_s": float(charged[in_flight].sum()) if split else None,
        **coverage_course(result),
        "fscore": result.surface.fscore, "wall_s": time.perf_counter() - t0,
    }


def _seconds(value: float | None) -> str:
    return "-" if value is None else f"{value:.0f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--planners", nargs="+", default=["esm-ipp-v2", "esm-ipp-v1"])
    parser.add_argument("--areas", nargs="+", default=["warehouse", "powerplant"])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--preset", default="default")
    parser.add_argument("--seconds", type=float, default=None)
    args = parser.parse_args()
    runs = []
    for area_name in args.areas:
        for seed in args.seeds:
            for planner_id in args.planners:
                r = fly(planner_id, area_name, seed, args.preset, args.seconds)
                runs.append(r)
                print(f"{area_name} seed {seed} {r['planner']}: coverage {r['coverage']:.4f}, "
                      f"CPU median {r['cpu_ms_median']:.1f} ms, {r['iterations']} plans, "
                      f"{r['nodes_last']} nodes, {r['reason']}, {r['wall_s']:.0f} s wall",
                      flush=True)
    print_table(
        f"ESM versions, preset {args.preset}",
        ["area", "seed", "planner", "coverage %", "explored m³ at 1/4, 1/2, 3/4 of the run",
         "95 % / 99 % of the end at s", "plans (in flight)", "charged s at rest / in flight",
         "CPU ms median (1st / 2nd half)", "CPU ms p90", "wall ms median", "nodes (last / max)",
         "path m", "F-score", "end"],
        [[r["area"], r["seed"], r["planner"], f"{100 * r['coverage']:.1f}",
          ", ".join(f"{q:.0f}" for q in r["quarters"]),
          f"{_seconds(r['t95_s'])} / {_seconds(r['t99_s'])}",
          f"{r['iterations']} ({r['calls_in_flight']})",
          f"{_seconds(r['charged_at_rest_s'])} / {_seconds(r['charged_in_flight_s'])}",
          f"{r['cpu_ms_median']:.1f} ({r['cpu_ms_median_first_half'] or 0:.1f} / "
          f"{r['cpu_ms_median_second_half'] or 0:.1f})", f"{r['cpu_ms_p90']:.1f}",
          f"{r['wall_ms_median'] or 0:.1f}", f"{r['nodes_last']} / {r['nodes_max']}",
          f"{r['path_length_m']:.0f}", f"{r['fscore']:.3f}",
          f"{r['reason']} at {r['ended_at_s']:.0f} s"] for r in runs],
    )
    path = write_json("esm_versions", {
        "command": "python benchmarks/esm_versions.py " + " ".join(sys.argv[1:]),
        "preset": args.preset, "runs": runs,
    })
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
