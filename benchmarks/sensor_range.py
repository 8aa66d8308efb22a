"""Planners flown with the depth camera's range (and field of view) set: what another camera
changes.

    .venv/bin/python benchmarks/sensor_range.py --planners esm-ipp splatplanner \
        --areas powerplant --seeds 0 1 2 --ranges 5 7 [--fov 115 99.3] [--seconds S]
        [--set nbvp.extension_m=3 ...] [--name NAME]

The benchmark's camera sees 90 x 73.7 degrees to 5 m for every planner on every area
(`docs/presets.md`). The FLYBO authors flew every planner on WAREHOUSE, PLATFORM A-B and
POWERPLANT with a wider and longer one: 115 x 99.3 degrees to 7 m (their `*_soa.launch` files
for Classic, Rapid and SplatPlanner; ESM's `large_fov` launches, with 7 m gain rays,
`docs/planners/esm.md`). This script measures how much of a difference between our results and
the paper's such a camera accounts for; `--fov` keeps the camera's pixels (160 x 120), so rays
lie farther apart; `--set` gives a planner other settings (the FLYBO authors' large-area ones:
`docs/RESULTS.md`). It does not change the benchmark: the runs are diagnostics, flown with the
default preset's every other setting and each planner's default config, except that a planner
whose config casts gain rays to a fixed length (`gain_range_m`) casts them as far as the camera
reaches (`--keep-gain-range` leaves them at their default) and what `--set` gives.

One run per planner, area, seed and range, one after the other in this process. Prints the
coverage and F-score of each run and the mean per planner, area and range; writes JSON.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import ValidationError

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from areas import load_area, load_ground_truth
from areas.registry import UnknownAreaError
from benchmarks.common import print_table, write_json
from flybo.versions import benchmark_version
from planners.registry import UnknownPlannerError, make, parse_id, spec
from sim.config import EpisodeConfig, preset
from sim.episode import run_episode

Fov = tuple[float, float]


def episode_config(range_m: float, fov_deg: Fov | None = None) -> EpisodeConfig:
    """The default preset with the camera reaching `range_m` and, when given, seeing `fov_deg`
    (horizontal, vertical degrees) with the same pixels."""
    base = preset("default")
    update: dict[str, Any] = {"max_range_m": range_m}
    if fov_deg is not None:
        update |= {"fov_h_deg": fov_deg[0], "fov_v_deg": fov_deg[1]}
    camera = base.camera.model_validate({**base.camera.model_dump(), **update})
    return base.model_copy(update={"camera": camera})


def planner_config(planner_id: str, range_m: float, keep_gain_range: bool) -> dict[str, Any]:
    """The planner's config overrides: gain rays as long as the camera's range, where the
    planner's config has a fixed gain-ray length."""
    fields = spec(planner_id).config_model.model_fields
    if keep_gain_range or "gain_range_m" not in fields:
        return {}
    return {"gain_range_m": range_m}


def parse_settings(items: list[str]) -> dict[str, dict[str, Any]]:
    """`PLANNER.FIELD=VALUE` items (VALUE as JSON) as {planner: {field: value}}; PLANNER is a
    planner name (every version of it) or id. Raises ValueError naming a malformed item."""
    settings: dict[str, dict[str, Any]] = {}
    for item in items:
        target, sep, raw = item.partition("=")
        planner, dot, field = target.partition(".")
        if not (sep and dot and planner and field):
            raise ValueError(f"{item!r} is not PLANNER.FIELD=VALUE")
        try:
            value = json.loads(raw)
        except json.JSONDecodeError:
            raise ValueError(f"{item!r}: {raw!r} is not a JSON value") from None
        settings.setdefault(planner, {})[field] = value
    return settings


def settings_for(planner_id: str, settings: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """The `--set` settings that apply to `planner_id`: its name's, then its id's."""
    name = parse_id(planner_id)[0]
    return {**settings.get(name, {}), **settings.get(planner_id, {})}


def fly(planner_id: str, area_name: str, seed: int, range_m: float, seconds: float | None,
        keep_gain_range: bool, fov_deg: Fov | None = None,
        settings: dict[str, Any] | None = None) -> dict[str, Any]:
    area = load_area(area_name)
    pid = spec(planner_id).id
    overrides = {**planner_config(pid, range_m, keep_gain_range), **(settings or {})}
    config = episode_config(range_m, fov_deg)
    fov = (config.camera.fov_h_deg, config.camera.fov_v_deg)
    t0 = time.perf_counter()
    result = run_episode(area, load_ground_truth(area), make(pid, overrides), config, seed,
                         planner_name=pid, seconds=seconds,
                         preset_name=f"default, camera {range_m:g} m, {fov[0]:g} x {fov[1]:g} deg")
    return {
        "planner": pid, "area": area_name, "seed": seed, "camera_range_m": range_m,
        "camera_fov_deg": list(fov),
        "planner_config": overrides, "coverage": result.coverage,
        "fscore": result.surface.fscore, "precision": result.surface.precision,
        "recall": result.surface.recall, "rmse_m": result.surface.rmse_m,
        "safety_stops": result.safety_stops, "status": result.status.value,
        "reason": result.reason, "ended_at_s": result.simulated_until,
        "iterations": result.iterations, "path_length_m": result.path_length_m,
        "collisions": result.collisions, "wall_s": time.perf_counter() - t0,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--planners", nargs="+", required=True)
    parser.add_argument("--areas", nargs="+", required=True)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--ranges", type=float, nargs="+", default=[5.0, 7.0],
                        help="camera ranges, metres")
    parser.add_argument("--seconds", type=float, default=None,
                        help="simulated seconds (default: each area's plateau time)")
    parser.add_argument("--fov", type=float, nargs=2, default=None, metavar=("H", "V"),
                        help="the camera's field of view, horizontal and vertical degrees "
                             "(default: the preset's), with the same pixels")
    parser.add_argument("--set", action="append", default=[], metavar="PLANNER.FIELD=VALUE",
                        help="a planner setting (VALUE as JSON) for a planner name or id, "
                             "e.g. nbvp.extension_m=3; repeatable")
    parser.add_argument("--keep-gain-range", action="store_true",
                        help="leave a planner's gain-ray length at its default")
    parser.add_argument("--name", default="sensor_range", help="JSON file name in results/")
    args = parser.parse_args()
    for r in args.ranges:
        if r <= 0:
            parser.error(f"--ranges: {r:g} is not a positive range in metres")
    fov_deg: Fov | None = None
    if args.fov is not None:
        if not all(0.0 < a < 180.0 for a in args.fov):
            parser.error(f"--fov: {args.fov[0]:g} x {args.fov[1]:g} is not a field of view "
                         "between 0 and 180 degrees")
        fov_deg = (args.fov[0], args.fov[1])
    try:
        settings = parse_settings(args.set)
    except ValueError as exc:
        parser.error(f"--set: {exc}")
    try:  # unknown names and settings fail here, before any flight
        for planner_id in args.planners:
            pid = spec(planner_id).id
            spec(pid).config_model.model_validate(
                {**planner_config(pid, max(args.ranges), args.keep_gain_range),
                 **settings_for(pid, settings)})
        for area_name in args.areas:
            load_area(area_name)
    except (UnknownPlannerError, UnknownAreaError) as exc:
        parser.error(str(exc))
    except ValidationError as exc:
        parser.error(f"--set: {exc}")
    runs = []
    for area_name in args.areas:
        for seed in args.seeds:
            for range_m in args.ranges:
                for planner_id in args.planners:
                    run = fly(planner_id, area_name, seed, range_m, args.seconds,
                              args.keep_gain_range, fov_deg,
                              settings_for(spec(planner_id).id, settings))
                    runs.append(run)
                    print(f"{area_name} seed {seed} camera {range_m:g} m "
                          f"{run['camera_fov_deg'][0]:g} x {run['camera_fov_deg'][1]:g} deg "
                          f"{run['planner']}: "
                          f"coverage {run['coverage']:.4f}, F {run['fscore']:.3f}, "
                          f"{run['iterations']} plans, {run['reason']}, "
                          f"{run['wall_s']:.0f} s wall", flush=True)
    print_table(
        "Runs", ["area", "seed", "camera m", "planner", "coverage %", "F-score", "plans",
                 "collisions", "end"],
        [[r["area"], r["seed"], f"{r['camera_range_m']:g}", r["planner"],
          f"{100 * r['coverage']:.1f}", f"{r['fscore']:.3f}", r["iterations"], r["collisions"],
          f"{r['reason']} at {r['ended_at_s']:.0f} s"] for r in runs])
    cells: dict[tuple[str, float, str], list[dict[str, Any]]] = {}
    for r in runs:
        cells.setdefault((r["area"], r["camera_range_m"], r["planner"]), []).append(r)
    h, v = runs[0]["camera_fov_deg"] if runs else (0.0, 0.0)
    print_table(
        f"Mean per planner, area and camera range (field of view {h:g} x {v:g} degrees)",
        ["area", "camera m", "planner", "runs", "coverage % (least-most)", "F-score"],
        [[area, f"{range_m:g}", pid, len(rs),
          f"{100 * np.mean([r['coverage'] for r in rs]):.1f} "
          f"({100 * min(r['coverage'] for r in rs):.1f}-"
          f"{100 * max(r['coverage'] for r in rs):.1f})",
          f"{np.mean([r['fscore'] for r in rs]):.3f}"]
         for (area, range_m, pid), rs in sorted(cells.items())])
    path = write_json(args.name, {
        "command": "python benchmarks/sensor_range.py " + " ".join(sys.argv[1:]),
        "benchmark": benchmark_version(), "camera_fov_deg": [h, v], "runs": runs,
    })
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
