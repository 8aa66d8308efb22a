"""Where a run left the observable volume unexplored, read from its recording.

    .venv/bin/python benchmarks/unexplored.py RECORDING [--area NAME] [--interval 50]
        [--band 1.0]

RECORDING is a run's recording (`flybo run` keeps one per run; `benchmarks/crash_sweep.py`
keeps them in `benchmarks/results/crash_sweep/`). Prints, every `--interval` simulated seconds,
the coverage as of the map keyframe then and the height band the vehicle flew in since the
previous line; then the observable volume and the part of it left unexplored at the end, per
height band of `--band` metres, and the largest connected unexplored regions with their boxes.
The area is the recording's own unless `--area` names it (an `AREA@SEED` layout needs it).
Writes `benchmarks/results/unexplored_<area>_<planner>.json`.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np
from scipy import ndimage

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks.common import print_table, write_json


def over_time(rec: Any, observable: np.ndarray, interval: float) -> list[dict[str, float]]:
    """Coverage at each interval's end, and the heights flown during the interval."""
    times, poses = rec.pose_times, rec.poses
    total = max(1, int(np.count_nonzero(observable)))
    rows = []
    for end in np.arange(interval, float(times[-1]) + interval, interval):
        end = min(float(end), float(times[-1]))
        state = rec.map_state_at(end)
        flown = poses[(times > end - interval) & (times <= end)]
        rows.append({"t_s": end,
                     "coverage": float(np.count_nonzero((state != 0) & observable)) / total,
                     "z_min_m": float(flown[:, 2].min()) if len(flown) else float("nan"),
                     "z_max_m": float(flown[:, 2].max()) if len(flown) else float("nan")})
    return rows


def by_height(observable: np.ndarray, missed: np.ndarray, z0: float, voxel: float,
              band: float) -> list[dict[str, float]]:
    """Observable and unexplored volume, m³, per height band."""
    per_layer_obs = observable.sum(axis=(0, 1)) * voxel**3
    per_layer_miss = missed.sum(axis=(0, 1)) * voxel**3
    heights = z0 + (np.arange(observable.shape[2]) + 0.5) * voxel
    rows = []
    for lo in np.arange(z0, heights[-1] + voxel, band):
        sel = (heights >= lo) & (heights < lo + band)
        if not sel.any():
            continue
        obs, miss = float(per_layer_obs[sel].sum()), float(per_layer_miss[sel].sum())
        rows.append({"z_from_m": float(lo), "z_to_m": float(lo + band), "observable_m3": obs,
                     "unexplored_m3": miss, "unexplored_share": miss / obs if obs else 0.0})
    return rows


def regions(missed: np.ndarray, origin: np.ndarray, voxel: float,
            count: int = 8) -> list[dict[str, Any]]:
    """The largest 6-connected unexplored regions, with their boxes in metres."""
    labels, n = ndimage.label(missed)
    if n == 0:
        return []
    sizes = np.bincount(labels.ravel())[1:]
    boxes = ndimage.find_objects(labels)
    out = []
    for i in np.argsort(-sizes)[:count]:
        box = boxes[i]
        lo = origin + np.array([s.start for s in box]) * voxel
        hi = origin + np.array([s.stop for s in box]) * voxel
        out.append({"volume_m3": float(sizes[i]) * voxel**3,
                    "box_min_m": lo.round(2).tolist(), "box_max_m": hi.round(2).tolist()})
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("recording", type=Path)
    parser.add_argument("--area", default=None, help="default: the recording's area")
    parser.add_argument("--interval", type=float, default=50.0, help="simulated seconds")
    parser.add_argument("--band", type=float, default=1.0, help="height band, metres")
    args = parser.parse_args()
    if args.interval <= 0 or args.band <= 0:
        raise SystemExit("--interval and --band must be positive")

    from areas import load_ground_truth
    from benchmarks.crash_sweep import sweep_area
    from sim.recording import Recording, RecordingError

    try:
        rec = Recording(args.recording)
    except (RecordingError, FileNotFoundError) as exc:
        raise SystemExit(str(exc)) from None
    area = sweep_area(args.area or rec.header["area"])
    if tuple(rec.header["grid_shape"]) != tuple(area.grid_shape):
        raise SystemExit(f"{args.recording}: its grid {rec.header['grid_shape']} is not area "
                         f"{area.name!r}'s {list(area.grid_shape)}; name the area with --area")
    truth = load_ground_truth(area)
    observable = truth.observable
    missed = observable & (rec.map_state_at(float("inf")) == 0)
    voxel = area.voxel_size
    series = over_time(rec, observable, args.interval)
    bands = by_height(observable, missed, float(area.bounds_min[2]), voxel, args.band)
    largest = regions(missed, area.bounds_min, voxel)

    planner = rec.header["planner"]
    print_table(f"{planner} on {area.name}: coverage over time", ["t s", "coverage", "flown z m"],
                [[f"{r['t_s']:.0f}", f"{r['coverage']:.3f}",
                  f"{r['z_min_m']:.1f}-{r['z_max_m']:.1f}"] for r in series])
    print_table("Unexplored at the end, per height band",
                ["z m", "observable m³", "unexplored m³", "unexplored share"],
                [[f"{r['z_from_m']:.1f}-{r['z_to_m']:.1f}", f"{r['observable_m3']:.1f}",
                  f"{r['unexplored_m3']:.1f}", f"{r['unexplored_share']:.3f}"] for r in bands])
    print_table("Largest unexplored regions", ["m³", "box from m", "box to m"],
                [[f"{r['volume_m3']:.1f}", r["box_min_m"], r["box_max_m"]] for r in largest])
    path = write_json(f"unexplored_{area.name}_{planner}", {
        "recording": str(args.recording), "area": area.name, "planner": planner,
        "over_time": series, "by_height": bands, "regions": largest})
    print(f"\nwrote {path}")


if __name__ == "__main__":
    main()
