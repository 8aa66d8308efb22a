"""CPU time of the occupancy update: this tree's kernel against another tree's, in lockstep.

    .venv/bin/python benchmarks/occupancy_cost.py --baseline DIR [--recordings R.npz ...]

The same depth frames (rendered once, default preset's stride and depth noise) are fused into
two maps, one by each tree's `integrate_rays`, frame by frame, alternating which goes first, three
times over; the CPU time of each call is summed. Interleaving call by call puts both kernels
under the same load, so the ratio holds on a busy machine where the absolute times do not. The
frames: the thin-structure room's gallery and door passes (`tests/sim/thin_scenes.py`), and the
poses (every second one, 5 Hz, at most 1,500) of each crash-sweep recording given
(`benchmarks/crash_sweep.py --recordings`, named `AREA--PLANNER--sSEED.npz`). The baseline's
kernel is passed those of this tree's arguments that it names (one may keep state the other does
not). "same map" says whether the two maps ended equal to the bit after every pass (log-odds,
states, and each voxel's batch tag and returns). Writes `benchmarks/results/occupancy_cost.json`.
"""

from __future__ import annotations

import argparse
import inspect
import sys
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(HERE))

import flybo  # noqa: E402, F401  pins the CPU kernels before NumPy loads, as flights do

_REPEATS = 3
_MAX_FRAMES = 1500


def _frames(area: Any, poses: list[Any]) -> list[tuple[Any, Any, Any]]:
    import numpy as np

    from sim.camera import CameraConfig, DepthCamera
    from sim.config import preset
    from sim.noise import add_depth_noise

    cfg = preset("default")
    stride = cfg.occupancy_pixel_stride
    camera = DepthCamera(area.vertices, area.triangles, CameraConfig())
    rng = np.random.default_rng(0)
    out = []
    for pose in poses:
        depth = add_depth_noise(camera.render(pose, stride=stride).depth, cfg.depth_noise, rng)
        ends, hit = camera.back_project(depth, pose, stride)
        out.append((pose.position, ends, hit))
    return out


def _adapted(kernel: Any, names: list[str], passed: list[str]) -> Any:
    """`kernel` (taking the arguments `names`) called with this tree's arguments `passed`."""
    picks = [passed.index(name) for name in names]

    def call(*args: Any) -> Any:
        return kernel(*(args[i] for i in picks))

    return call


def _same_map(a: Any, b: Any) -> bool:
    """Whether two maps fused from the same frames hold the same log-odds, states and per-voxel
    words (batch tags and returns) to the bit."""
    import numpy as np

    return (a.known_count == b.known_count
            and np.array_equal(a.log_odds.view(np.uint32), b.log_odds.view(np.uint32))
            and np.array_equal(a.state, b.state)
            and np.array_equal(a._voxels, b._voxels))


def _scenes(recordings: list[Path]) -> list[tuple[str, Any, list[tuple[Any, Any, Any]]]]:
    import numpy as np

    from areas import load_area
    from sim.geometry import Pose
    from sim.recording import Recording
    from tests.sim.thin_scenes import DOORS, door_pass, gallery_pass, thin_room

    room, _ = thin_room()
    passes = gallery_pass() + [p for door in DOORS for p in door_pass(door)]
    scenes = [("thin room", room, _frames(room, passes))]
    for path in recordings:
        area = load_area(path.name.split("--", 1)[0])
        recorded = Recording(path).poses
        poses = [Pose(recorded[i, :3].astype(np.float64), float(recorded[i, 3]))
                 for i in range(0, len(recorded), 2)][:_MAX_FRAMES]
        scenes.append((path.name, area, _frames(area, poses)))
    return scenes


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", type=Path, required=True,
                        help="another tree's folder, whose sim/occupancy_kernels.py is compared")
    parser.add_argument("--recordings", type=Path, nargs="*", default=[],
                        help="crash-sweep recordings whose poses to fuse")
    args = parser.parse_args(argv)
    from areas.registry import all_area_names

    known = set(all_area_names())
    for path in args.recordings:
        if not path.is_file() or "--" not in path.name:
            raise SystemExit(f"--recordings {path}: not a crash-sweep recording (AREA--...npz)")
        if path.name.split("--", 1)[0] not in known:
            raise SystemExit(f"--recordings {path}: no area named "
                             f"{path.name.split('--', 1)[0]!r} (`flybo areas list`)")

    import sim.occupancy as occupancy
    from benchmarks.common import baseline_module, print_table, write_json
    from tests.sim.thin_scenes import new_map

    baseline = baseline_module(args.baseline, "sim/occupancy_kernels.py",
                               "baseline_occupancy_kernels")
    own = occupancy.integrate_rays
    ours = list(inspect.signature(own.py_func).parameters)
    theirs = list(inspect.signature(baseline.integrate_rays.py_func).parameters)
    if not set(theirs) <= set(ours):
        raise SystemExit(f"--baseline {args.baseline}: its integrate_rays takes arguments this "
                         f"tree's map does not pass ({sorted(set(theirs) - set(ours))})")
    # Both are called through the same adapter, which passes each the arguments it names.
    kernels = {"this": _adapted(own, ours, ours),
               "baseline": _adapted(baseline.integrate_rays, theirs, ours)}
    rows, measured = [], []
    try:
        for name, area, frames in _scenes(args.recordings):
            if not frames:
                print(f"{name}: no poses, skipped", flush=True)
                continue
            for kernel in kernels.values():  # compiled (or loaded from numba's cache) first
                occupancy.integrate_rays = kernel
                new_map(area).integrate(*frames[0])
            cpu = dict.fromkeys(kernels, 0.0)
            same = True
            for repeat in range(_REPEATS):
                maps = {label: new_map(area) for label in kernels}
                for n, frame in enumerate(frames):
                    order = list(kernels) if (n + repeat) % 2 == 0 else list(kernels)[::-1]
                    for label in order:
                        occupancy.integrate_rays = kernels[label]
                        t0 = time.process_time()
                        maps[label].integrate(*frame)
                        cpu[label] += time.process_time() - t0
                same = same and _same_map(maps["this"], maps["baseline"])
            calls = _REPEATS * len(frames)
            this_ms, base_ms = (1000.0 * cpu[k] / calls for k in ("this", "baseline"))
            rows.append([name, len(frames), f"{this_ms:.3f}", f"{base_ms:.3f}",
                         f"{this_ms / base_ms:.3f}", "yes" if same else "NO"])
            measured.append({"scene": name, "frames": len(frames), "this_ms": this_ms,
                             "baseline_ms": base_ms, "same_map": same})
            print(f"{name}: {this_ms / base_ms:.3f}", flush=True)
    finally:
        occupancy.integrate_rays = own
    print_table("Occupancy update, CPU ms per frame (lockstep, default preset's rays)",
                ["frames of", "frames", "this", "baseline", "ratio", "same map"], rows)
    path = write_json("occupancy_cost", {"baseline": str(args.baseline), "scenes": measured})
    print(f"\nwrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
