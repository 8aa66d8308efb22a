"""Where a run's memory goes: resident and peak memory at each stage of one flight.

    .venv/bin/python benchmarks/run_memory.py [--planners classic] [--areas offices-c]
        [--seconds S] [--preset default] [--baseline DIR]

Each run flies alone in a fresh process (seed 0, the area's plateau time unless `--seconds`),
which reads its resident set (`VmRSS`) and its peak so far (`ru_maxrss`) after the libraries are
imported, after the area and its ground truth are loaded, and at the end of the run (the final
reconstruction and its scoring included). It also reports the bytes the ground
truth's surface cloud keeps resident for the whole run, and the final reconstruction's own
peak: the resident set before the TSDF is meshed and the highest resident set while it is
(the kernel's high-water mark, reset just before: `/proc/self/clear_refs`), and how long the
meshing took.

`--baseline DIR` flies every run a second time with the code of another tree (an unpacked
`git archive` of an earlier commit), interleaved with this tree's runs, and prints the ratios
of the two measured in this one invocation. The default preset charges planning CPU time to the
simulated clock, so two runs of it fly slightly differently; `--preset exact` flies the same
flight in both trees, and only the code's own memory differs.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent.parent


def _peak_rss_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _status_mib(field: str) -> float:
    """A memory field of /proc/self/status (VmRSS: resident now, VmHWM: its high-water mark)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(f"{field}:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def _vm_rss_mib() -> float:
    return _status_mib("VmRSS")


def _watch_reconstruction(stages: dict[str, Any]) -> None:
    """Record resident memory before the TSDF is meshed and its high-water mark while it is."""
    from sim.tsdf import TsdfVolume

    mesh = TsdfVolume.mesh

    def watched(self: Any) -> Any:
        before = _vm_rss_mib()
        Path("/proc/self/clear_refs").write_text("5")  # resets VmHWM to the resident set
        t0 = time.perf_counter()
        out = mesh(self)
        stages["reconstruction"] = (before, _status_mib("VmHWM"), time.perf_counter() - t0)
        return out

    TsdfVolume.mesh = watched  # type: ignore[method-assign]


def _child(planner: str, area_name: str, seconds: float | None,
           preset_name: str) -> dict[str, Any]:
    """One flight, in this process, with the code of the tree it was started in."""
    import flybo  # noqa: F401  before NumPy: it pins the CPU kernels
    from areas import load_area, load_ground_truth
    from planners.registry import make, spec
    from sim.config import preset
    from sim.episode import run_episode

    stages: dict[str, Any] = {"imported": (_vm_rss_mib(), _peak_rss_mib())}
    _watch_reconstruction(stages)
    area = load_area(area_name)
    truth = load_ground_truth(area)
    stages["truth_loaded"] = (_vm_rss_mib(), _peak_rss_mib())
    surface = getattr(truth, "surface", None)  # trees before the packed cloud held float32
    cloud_bytes = surface.nbytes if surface is not None else truth.surface_points.nbytes
    planner_id = spec(planner).id
    wall0 = time.perf_counter()
    result = run_episode(area, truth, make(planner_id), preset(preset_name), 0,
                         planner_name=planner_id, preset_name=preset_name, seconds=seconds)
    stages["run_ended"] = (_vm_rss_mib(), _peak_rss_mib())
    return {"planner": planner_id, "area": area_name, "simulated_until": result.simulated_until,
            "coverage": result.coverage, "fscore": result.surface.fscore,
            "wall_s": time.perf_counter() - wall0, "cloud_mib": cloud_bytes / 2**20,
            "stages": stages}


def _fly(tree: Path, planner: str, area: str, seconds: float | None,
         preset_name: str) -> dict[str, Any]:
    """One flight in a fresh process running `tree`'s code (this script's own measuring code)."""
    cmd = [sys.executable, str(Path(__file__).resolve()), "--child-tree", str(tree),
           "--planners", planner, "--areas", area, "--preset", preset_name]
    if seconds is not None:
        cmd += ["--seconds", str(seconds)]
    out = subprocess.run(cmd, cwd=tree, check=True, capture_output=True, text=True)
    return dict(json.loads(out.stdout.strip().splitlines()[-1]))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--planners", default="classic", help="comma-separated planner names")
    parser.add_argument("--areas", default="offices-c", help="comma-separated areas")
    parser.add_argument("--seconds", type=float, default=None,
                        help="simulated seconds (default: each area's plateau time)")
    parser.add_argument("--preset", default="default", help="the runs' preset")
    parser.add_argument("--baseline", type=Path, default=None,
                        help="another tree's folder, flown beside this one")
    parser.add_argument("--child-tree", type=Path, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child_tree is not None:
        # Every package from that tree (the measuring code above imports none of them).
        sys.path.insert(0, str(args.child_tree))
        print(json.dumps(_child(args.planners, args.areas, args.seconds, args.preset)))
        return 0
    sys.path.insert(0, str(HERE))
    from benchmarks.common import checked_baseline, print_table, write_json

    baseline = checked_baseline(args.baseline)
    trees = [("this", HERE)] + ([("baseline", baseline)] if baseline else [])
    runs: list[dict[str, Any]] = []
    for area in (a.strip() for a in args.areas.split(",")):
        for planner in (p.strip() for p in args.planners.split(",")):
            for label, tree in trees:
                run = _fly(tree, planner, area, args.seconds, args.preset)
                run["tree"] = label
                runs.append(run)
                print(f"{label}: {run['planner']} {area}: peak {run['stages']['run_ended'][1]:.0f}"
                      f" MiB", flush=True)
    rows = []
    for r in runs:
        s = r["stages"]
        rows.append([r["tree"], r["planner"], r["area"], f"{r['simulated_until']:.0f}",
                     f"{100 * r['coverage']:.1f}", f"{100 * r['fscore']:.2f}",
                     f"{r['cloud_mib']:.0f}", f"{s['imported'][0]:.0f}",
                     f"{s['truth_loaded'][0]:.0f}", f"{s['truth_loaded'][1]:.0f}",
                     f"{s['reconstruction'][0]:.0f}", f"{s['reconstruction'][1]:.0f}",
                     f"{s['run_ended'][0]:.0f}", f"{s['run_ended'][1]:.0f}"])
    print_table(f"Memory of one run (MiB; preset {args.preset}, seed 0)",
                ["tree", "planner", "area", "until s", "coverage %", "F %", "truth cloud",
                 "imported", "truth loaded", "peak so far", "before mesh", "meshing peak",
                 "run ended", "peak"], rows)
    if args.baseline:
        print("\nratio this / baseline (peak of the whole run; meshing peak above the resident"
              " set before it):")
        for this, base in zip(runs[0::2], runs[1::2], strict=True):
            ratio = this["stages"]["run_ended"][1] / base["stages"]["run_ended"][1]
            mesh_this, mesh_base = (r["stages"]["reconstruction"][1]
                                    - r["stages"]["reconstruction"][0] for r in (this, base))
            seconds = this["stages"]["reconstruction"][2] / base["stages"]["reconstruction"][2]
            print(f"  {this['planner']} {this['area']}: whole run {ratio:.3f}; meshing "
                  f"{mesh_this:.0f} vs {mesh_base:.0f} MiB ({mesh_this / mesh_base:.3f}), "
                  f"its time {seconds:.2f}x")
    path = write_json("run_memory", {"runs": runs, "seconds": args.seconds,
                                     "preset": args.preset})
    print(f"\nwrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
