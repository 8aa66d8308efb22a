"""Which stage of a run sets its peak resident memory, and what the TSDF's block table did.

    .venv/bin/python benchmarks/stage_peaks.py [--planner splatplanner] [--area facility-c]
        [--seed 0] [--seconds S] [--preset default] [--no-recording] [--out NAME]

One run, as the crash sweep and the workers fly it (its recording written to a temporary
folder unless `--no-recording`), in this process. Before each call of a stage the kernel's
high-water mark is reset to the resident set (`/proc/self/clear_refs`) and read after it, so
each stage's row is the highest resident set any one of its calls reached and how far that
call rose above the resident set it started from; "between" is everything outside the stages
(the loop, physics, the safety monitor). The stages: a camera frame (render, noise, occupancy
and TSDF fusion), the recorder's frame (map keyframes, surface snapshots), a planner call, the
plan check, the final measures (the mesh and its scoring) and saving the recording.

The TSDF's block table: the blocks the area's surface was expected to need, the capacity the
table started with, every growth (at which fused frame, from what to what) and the blocks at
the end. Linux only (`/proc`).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(HERE))

import flybo  # noqa: E402, F401  before NumPy: it pins the CPU kernels

STAGES = ("camera frame", "recorder frame", "planner call", "plan check", "final measures",
          "recording save")


def _status_mib(field: str) -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(f"{field}:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def _reset_high_water() -> None:
    Path("/proc/self/clear_refs").write_text("5")


class StagePeaks:
    """The highest resident set (MiB) each stage reached and the rise of that call."""

    def __init__(self) -> None:
        self.peaks: dict[str, tuple[float, float]] = {}

    def note(self, stage: str, high: float, before: float) -> None:
        if stage not in self.peaks or high > self.peaks[stage][0]:
            # The mark is reset to the resident set a moment after `before` is read.
            self.peaks[stage] = (high, max(0.0, high - before))

    def wrap(self, owner: Any, name: str, stage: str) -> None:
        inner: Callable[..., Any] = getattr(owner, name)

        def watched(*args: Any, **kwargs: Any) -> Any:
            self.note("between", _status_mib("VmHWM"), _status_mib("VmRSS"))
            before = _status_mib("VmRSS")
            _reset_high_water()
            try:
                return inner(*args, **kwargs)
            finally:
                self.note(stage, _status_mib("VmHWM"), before)
                _reset_high_water()

        setattr(owner, name, watched)


def _watch_block_table(events: dict[str, Any]) -> None:
    from sim import episode_loop
    from sim.tsdf import TsdfVolume

    made, make_room, finish = TsdfVolume.__init__, TsdfVolume._make_room, \
        episode_loop.EpisodeLoop.finish

    def init(self: TsdfVolume, *args: Any, **kwargs: Any) -> None:
        made(self, *args, **kwargs)
        expected = args[3] if len(args) > 3 else kwargs.get("expected_blocks", 0)
        events.update(expected=int(expected), capacity=int(self.grid.hashmap().capacity()),
                      growths=[])

    def room(self: TsdfVolume, touched: int) -> None:
        table = self.grid.hashmap()
        size, capacity = int(table.size()), int(table.capacity())
        make_room(self, touched)
        if table.capacity() != capacity:
            events["growths"].append({"frame": self.frames, "blocks": size, "touched": touched,
                                      "from": capacity, "to": int(table.capacity())})

    def end(self: Any, ending: Any) -> Any:
        table = self.sensing.tsdf.grid.hashmap()
        events.update(final_blocks=int(table.size()), frames=self.sensing.tsdf.frames)
        return finish(self, ending)

    TsdfVolume.__init__ = init  # type: ignore[method-assign]
    TsdfVolume._make_room = room  # type: ignore[method-assign]
    episode_loop.EpisodeLoop.finish = end  # type: ignore[method-assign]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--planner", default="splatplanner")
    parser.add_argument("--area", default="facility-c")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--seconds", type=float, default=None,
                        help="simulated seconds (default: the area's plateau time)")
    parser.add_argument("--preset", default="default")
    parser.add_argument("--no-recording", action="store_true")
    parser.add_argument("--out", default="stage_peaks",
                        help="the JSON's name in benchmarks/results/")
    args = parser.parse_args(argv)

    from areas import load_area, load_ground_truth
    from benchmarks.common import print_table, write_json
    from flybo.versions import benchmark_version
    from planners.registry import make, spec
    from sim import episode_loop, episode_recorder, sensing
    from sim.config import preset
    from sim.episode import run_episode

    peaks, table = StagePeaks(), {}  # type: ignore[var-annotated]
    peaks.wrap(sensing.Sensing, "frame", "camera frame")
    peaks.wrap(episode_recorder.EpisodeRecorder, "frame", "recorder frame")
    peaks.wrap(episode_recorder.EpisodeRecorder, "save", "recording save")
    peaks.wrap(episode_loop, "call_planner", "planner call")
    peaks.wrap(episode_loop.EpisodeLoop, "_accept", "plan check")
    peaks.wrap(episode_loop.EpisodeLoop, "finish", "final measures")
    _watch_block_table(table)

    area = load_area(args.area)
    truth = load_ground_truth(area)
    planner_id = spec(args.planner).id
    loaded = _status_mib("VmHWM")
    _reset_high_water()
    wall0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as folder:
        recording = None if args.no_recording else Path(folder) / "run.npz"
        result = run_episode(area, truth, make(planner_id), preset(args.preset), args.seed,
                             planner_name=planner_id, preset_name=args.preset,
                             seconds=args.seconds, recording_path=recording)
    peaks.note("between", _status_mib("VmHWM"), _status_mib("VmRSS"))
    rows = [[stage, f"{high:.0f}", f"{rise:.0f}"] for stage, (high, rise)
            in sorted(peaks.peaks.items(), key=lambda kv: -kv[1][0])]
    title = (f"{planner_id} on {args.area}, seed {args.seed}, {result.simulated_until:.0f} s, "
             f"benchmark {benchmark_version()}: highest resident set per stage (MiB)")
    print_table(title, ["stage", "highest", "rise of that call"], rows)
    print(f"\nimports, area and ground truth loaded: highest {loaded:.0f} MiB")
    print(f"TSDF block table: expected {table['expected']:,} blocks, started with room for "
          f"{table['capacity']:,}; {len(table['growths'])} growth(s)"
          + "".join(f"; at fused frame {g['frame']} of {table['frames']}: {g['blocks']:,} + "
                    f"{g['touched']} blocks, {g['from']:,} -> {g['to']:,}"
                    for g in table["growths"])
          + f"; {table['final_blocks']:,} blocks at the end "
          f"({table['final_blocks'] / table['expected']:.3f} of expected)")
    path = write_json(args.out, {
        "planner": planner_id, "area": args.area, "seed": args.seed, "preset": args.preset,
        "benchmark": benchmark_version(), "recording": not args.no_recording,
        "simulated_until": result.simulated_until, "coverage": result.coverage,
        "wall_s": time.perf_counter() - wall0, "loaded_mib": loaded,
        "stages": {k: {"highest_mib": h, "rise_mib": r} for k, (h, r) in peaks.peaks.items()},
        "block_table": table})
    print(f"\nwrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
