"""Memory of writing a run's recording: `RecordingWriter.save` against one concatenation.

    .venv/bin/python benchmarks/recording_memory.py [--snapshots 24] [--points 400000]
        [--keyframes 400] [--changed 40000]

Fills a `RecordingWriter` with synthetic keyframes (changed voxel indices and states), plans and
thinned surface snapshots of the given sizes, then writes it twice in one process: with `save`,
which writes each flat sequence item by item, and, as the reference, with
`np.savez_compressed` of every sequence concatenated first (how the archive was written up to
benchmark 2026.12-12). Prints the peak of Python-tracked allocations (`tracemalloc`: NumPy
reports its buffers to it) above what the writer already held, and the ratio. Writes
`benchmarks/results/recording_memory.json`.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
import tracemalloc
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks.common import print_table, write_json
from sim.recording import FORMAT, VERSION, RecordingWriter


def filled_writer(snapshots: int, points: int, keyframes: int, changed: int) -> RecordingWriter:
    rng = np.random.default_rng(0)
    writer = RecordingWriter(header={"grid_shape": [400, 300, 60]})
    cells = 400 * 300 * 60
    for k in range(keyframes):
        state = np.zeros(cells, dtype=np.uint8)
        state[rng.integers(0, cells, changed)] = rng.integers(1, 3, changed, dtype=np.uint8)
        writer._key_times.append(float(k))
        writer._key_indices.append(np.flatnonzero(state).astype(np.uint32))
        writer._key_states.append(state[writer._key_indices[-1]])
        writer.pose(float(k), rng.uniform(0.0, 9.0, 3), 0.0)
        writer.plan(float(k), rng.uniform(0.0, 9.0, (4, 4)))
    for s in range(snapshots):
        writer._surface_times.append(float(s))
        writer._surfaces.append(rng.uniform(0.0, 40.0, (points, 3)).astype(np.float32))
    return writer


def concatenated_save(writer: RecordingWriter, path: Path) -> None:
    """The reference: every sequence concatenated, then one `np.savez_compressed`."""
    def flat(items: list[np.ndarray], dtype: type, width: int | None) -> np.ndarray:
        shape = (0,) if width is None else (0, width)
        return np.concatenate(items).astype(dtype) if items else np.zeros(shape, dtype=dtype)

    def offsets(items: list[np.ndarray]) -> np.ndarray:
        return np.concatenate([[0], np.cumsum([len(i) for i in items])]).astype(np.int64)

    header = {**writer.header, "format": FORMAT, "version": VERSION}
    np.savez_compressed(
        path, header=np.array(json.dumps(header)),
        pose_times=np.array(writer._pose_times), poses=np.array(writer._poses),
        keyframe_times=np.array(writer._key_times),
        keyframe_offsets=offsets(writer._key_indices),
        keyframe_indices=flat(writer._key_indices, np.uint32, None),
        keyframe_states=flat(writer._key_states, np.uint8, None),
        plan_times=np.array(writer._plan_times), plan_offsets=offsets(writer._plans),
        plan_waypoints=flat(writer._plans, np.float32, 4),
        surface_times=np.array(writer._surface_times),
        surface_offsets=offsets(writer._surfaces),
        surface_points=flat(writer._surfaces, np.float32, 3))


def measured(write: Callable[[Path], None], folder: Path) -> tuple[float, float, int]:
    """(peak MiB above the start, seconds, file bytes) of one write."""
    path = folder / "r.npz"
    tracemalloc.start()
    tracemalloc.reset_peak()
    base = tracemalloc.get_traced_memory()[0]
    t0 = time.perf_counter()
    write(path)
    seconds = time.perf_counter() - t0
    peak = tracemalloc.get_traced_memory()[1] - base
    tracemalloc.stop()
    size = path.stat().st_size
    path.unlink()
    return peak / 2**20, seconds, size


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--snapshots", type=int, default=24)
    parser.add_argument("--points", type=int, default=400_000)
    parser.add_argument("--keyframes", type=int, default=400)
    parser.add_argument("--changed", type=int, default=40_000)
    args = parser.parse_args()
    writer = filled_writer(args.snapshots, args.points, args.keyframes, args.changed)
    held = sum(a.nbytes for seq in (writer._key_indices, writer._key_states, writer._surfaces)
               for a in seq) / 2**20
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        new = measured(writer.save, folder)
        old = measured(lambda p: concatenated_save(writer, p), folder)
    rows = [["save (item by item)", f"{new[0]:.1f}", f"{new[1]:.2f}", f"{new[2] / 2**20:.1f}"],
            ["concatenated, savez_compressed", f"{old[0]:.1f}", f"{old[1]:.2f}",
             f"{old[2] / 2**20:.1f}"]]
    print_table(f"Writing a recording that holds {held:.0f} MiB of sequences",
                ["writer", "peak above start, MiB", "seconds", "file MiB"], rows)
    ratio = new[0] / old[0] if old[0] else None
    print(f"\npeak ratio, save / concatenated: {ratio:.3f}" if ratio is not None else "")
    write_json("recording_memory", {
        "args": vars(args), "held_mib": held,
        "save": {"peak_mib": new[0], "seconds": new[1], "bytes": new[2]},
        "concatenated": {"peak_mib": old[0], "seconds": old[1], "bytes": old[2]},
        "peak_ratio": ratio})


if __name__ == "__main__":
    main()
