"""Memory of a run's recording: what the writer holds while the run flies, and its `save`.

    .venv/bin/python benchmarks/recording_memory.py [--snapshots 24] [--points 400000]
        [--keyframes 400] [--changed 40000]

Fills a `RecordingWriter` through its methods with synthetic keyframes (``--changed`` voxels of
a 400 x 300 x 60 grid change between keyframes), plans and surface snapshots of ``--points``
random points each, then writes it. Prints, from Python-tracked allocations (`tracemalloc`:
NumPy reports its buffers to it): what the writer holds once filled, beside the bytes of its
keyframes and snapshots (what a writer keeping them in memory holds: the recording's writer
up to benchmark 2026.12-16), and the peak of `save` above that. Writes
`benchmarks/results/recording_memory.json`.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks.common import print_table, write_json
from sim.recording import Recording, RecordingWriter

SHAPE = (400, 300, 60)
# Finer than any two random points: thinning keeps every snapshot point.
SNAPSHOT_VOXEL_M = 1e-4


def fill(writer: RecordingWriter, snapshots: int, points: int, keyframes: int,
         changed: int) -> None:
    rng = np.random.default_rng(0)
    state = np.zeros(SHAPE, dtype=np.uint8)
    flat = state.reshape(-1)
    for k in range(keyframes):
        cells = rng.integers(0, flat.size, changed)
        flat[cells] = rng.integers(1, 3, changed, dtype=np.uint8)
        writer.map_keyframe(float(k), state)
        writer.pose(float(k), rng.uniform(0.0, 9.0, 3), 0.0)
        writer.plan(float(k), rng.uniform(0.0, 9.0, (4, 4)))
    for s in range(snapshots):
        writer.surface(float(s), rng.uniform(0.0, 40.0, (points, 3)), SNAPSHOT_VOXEL_M)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--snapshots", type=int, default=24)
    parser.add_argument("--points", type=int, default=400_000)
    parser.add_argument("--keyframes", type=int, default=400)
    parser.add_argument("--changed", type=int, default=40_000)
    args = parser.parse_args()
    # Compile and import what the writer uses first: only its data is traced.
    warm = RecordingWriter(header={})
    warm.surface(0.0, np.zeros((8, 3)), SNAPSHOT_VOXEL_M)
    warm.close()
    writer = RecordingWriter(header={"grid_shape": list(SHAPE)})
    tracemalloc.start()
    base = tracemalloc.get_traced_memory()[0]
    t0 = time.perf_counter()
    fill(writer, args.snapshots, args.points, args.keyframes, args.changed)
    fill_s = time.perf_counter() - t0
    # The previous keyframe's grid is held in either form: count it beside the sequences.
    grid = int(np.prod(SHAPE))
    held = tracemalloc.get_traced_memory()[0] - base
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "r.npz"
        tracemalloc.reset_peak()
        before_save = tracemalloc.get_traced_memory()[0]
        t0 = time.perf_counter()
        writer.save(path)
        save_s = time.perf_counter() - t0
        save_peak = tracemalloc.get_traced_memory()[1] - before_save
        tracemalloc.stop()
        size = path.stat().st_size
        saved = Recording(path)
        # What a writer keeping the sequences in memory holds: their bytes.
        given = sum(saved.array(name).nbytes for name in (
            "keyframe_indices", "keyframe_states", "plan_waypoints", "surface_points"))
        assert len(saved.array("surface_points")) == args.snapshots * args.points
    writer.close()
    mib = 2**20
    rows = [["spooled to a temporary file (this writer)", f"{held / mib:.1f}",
             f"{save_peak / mib:.1f}", f"{fill_s:.2f}", f"{save_s:.2f}"],
            ["kept in memory (the reference)", f"{(given + grid) / mib:.1f}", "", "", ""]]
    print_table(f"A recording of {given / mib:.0f} MiB of keyframes and snapshots "
                f"(file {size / mib:.0f} MiB)",
                ["writer", "held when filled, MiB", "save's peak above, MiB", "fill s",
                 "save s"], rows)
    ratio = held / (given + grid)
    print(f"\nheld ratio, spooled / in memory: {ratio:.3f}")
    write_json("recording_memory", {
        "args": vars(args), "sequences_mib": given / mib, "held_mib": held / mib,
        "in_memory_mib": (given + grid) / mib, "held_ratio": ratio,
        "save_peak_mib": save_peak / mib, "fill_s": fill_s, "save_s": save_s, "bytes": size})


if __name__ == "__main__":
    main()
