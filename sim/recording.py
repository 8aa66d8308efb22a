"""Run recordings: poses, map keyframes, plans and surface snapshots in one compact file.

Format `flybo-recording` version 1 is a NumPy `.npz` (zip, deflate) whose arrays are listed in
`docs/recording.md`. Variable-length sequences are stored flat with an `*_offsets` array
(K + 1,) so that item i is `flat[offsets[i]:offsets[i + 1]]`.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numba
import numpy as np
import numpy.typing as npt

from sim.voxel_grid import IndexBox

FORMAT = "flybo-recording"
VERSION = 1


class RecordingError(ValueError):
    """The file is not a recording this version can read."""


def _offsets(lengths: list[int]) -> npt.NDArray[np.int64]:
    """(K + 1,) start of each item in the flat sequence, and its end."""
    offsets = np.zeros(len(lengths) + 1, dtype=np.int64)
    offsets[1:] = np.cumsum(lengths) if lengths else []
    return offsets


def _write_array(archive: zipfile.ZipFile, name: str, array: np.ndarray) -> None:
    with archive.open(f"{name}.npy", "w", force_zip64=True) as fh:
        np.lib.format.write_array(fh, np.asanyarray(array), allow_pickle=False)


class Spool:
    """A sequence of arrays of one dtype and row width kept in an unnamed temporary file
    (`tempfile`, under TMPDIR) as they come, not in memory: a large area's keyframes and
    surface snapshots reach hundreds of MiB by the end of a run, which is when its final
    measures need the most memory. `write_npy` writes them as one array, item after item."""

    def __init__(self, dtype: npt.DTypeLike, width: int | None) -> None:
        self.dtype, self.width = np.dtype(dtype), width
        self.lengths: list[int] = []
        self._file = tempfile.TemporaryFile()  # noqa: SIM115  held for the run, closed by `close`

    def append(self, item: np.ndarray) -> None:
        row = () if self.width is None else (self.width,)
        array = np.ascontiguousarray(item, dtype=self.dtype)
        if array.shape[1:] != row:
            raise ValueError(f"an item of shape {array.shape} in a sequence of rows {row}")
        self._file.write(array.data)
        self.lengths.append(len(array))

    def write_npy(self, archive: zipfile.ZipFile, name: str) -> None:
        total = sum(self.lengths)
        header = {"descr": np.lib.format.dtype_to_descr(self.dtype), "fortran_order": False,
                  "shape": (total,) if self.width is None else (total, self.width)}
        self._file.flush()
        self._file.seek(0)
        with archive.open(f"{name}.npy", "w", force_zip64=True) as fh:
            np.lib.format.write_array_header_1_0(fh, header)
            shutil.copyfileobj(self._file, fh, 1 << 20)
        self._file.seek(0, os.SEEK_END)

    def close(self) -> None:
        self._file.close()


# Past this many cells over the snapshot's bounds (a bit each), thinning sorts cell keys instead.
MAX_BITMAP_CELLS = 1 << 27  # 16 MiB of bits


def thinned(points: np.ndarray, voxel_m: float, chunk: int = 1 << 20) -> np.ndarray:
    """The first of `points` (N, 3) in each cell of a `voxel_m` grid, in their order.

    A cell is `floor(point / voxel_m)` in float64. One compiled pass marks each cell in a
    bitmap over the cells' bounds as its first point is met; past `MAX_BITMAP_CELLS` cells the
    cell keys are computed `chunk` points at a time and sorted, so that a snapshot of millions
    of points needs one int64 key per point beside them, not float64 and int64 copies."""
    n = len(points)
    if n == 0:
        return points
    cloud = np.ascontiguousarray(points)
    lo, hi = _cell_bounds(cloud, float(voxel_m))
    span = hi - lo + 1
    if int(np.prod(span)) <= MAX_BITMAP_CELLS:
        seen = np.zeros((int(np.prod(span)) + 7) // 8, dtype=np.uint8)
        return points[_first_in_cells(cloud, float(voxel_m), lo, span, seen)]
    keys = np.empty(n, dtype=np.int64)
    for s in range(0, n, chunk):
        c = np.floor(np.asarray(points[s:s + chunk], dtype=np.float64) / voxel_m).astype(
            np.int64) - lo
        keys[s:s + len(c)] = (c[:, 0] * span[1] + c[:, 1]) * span[2] + c[:, 2]
    _, first = np.unique(keys, return_index=True)
    return points[np.sort(first)]


@numba.njit(cache=True)
def _cell_bounds(points: npt.NDArray[Any], voxel: float) -> tuple[
    npt.NDArray[np.int64], npt.NDArray[np.int64]
]:  # pragma: no cover - numba
    """The least and greatest cell (3,) of `points` (N, 3)."""
    lo = np.full(3, np.iinfo(np.int64).max, np.int64)
    hi = np.full(3, np.iinfo(np.int64).min, np.int64)
    for i in range(points.shape[0]):
        for a in range(3):
            c = np.int64(np.floor(np.float64(points[i, a]) / voxel))
            lo[a] = min(lo[a], c)
            hi[a] = max(hi[a], c)
    return lo, hi


@numba.njit(cache=True)
def _first_in_cells(points: npt.NDArray[Any], voxel: float, lo: npt.NDArray[np.int64],
                    span: npt.NDArray[np.int64],
                    seen: npt.NDArray[np.uint8]) -> npt.NDArray[np.bool_]:  # pragma: no cover
    """True on each point whose cell no earlier point is in."""
    keep = np.zeros(points.shape[0], np.bool_)
    for i in range(points.shape[0]):
        cx = np.int64(np.floor(np.float64(points[i, 0]) / voxel)) - lo[0]
        cy = np.int64(np.floor(np.float64(points[i, 1]) / voxel)) - lo[1]
        cz = np.int64(np.floor(np.float64(points[i, 2]) / voxel)) - lo[2]
        key = (cx * span[1] + cy) * span[2] + cz
        byte, bit = key >> 3, np.uint8(1 << (key & 7))
        if not seen[byte] & bit:
            seen[byte] |= bit
            keep[i] = True
    return keep


@dataclass
class RecordingWriter:
    """Collects a run as it happens, its long sequences in temporary files (`Spool`); `save`
    writes the archive, `close` lets the files go."""

    header: dict[str, Any]
    _pose_times: list[float] = field(default_factory=list)
    _poses: list[np.ndarray] = field(default_factory=list)
    _key_times: list[float] = field(default_factory=list)
    _key_indices: Spool = field(default_factory=lambda: Spool(np.uint32, None))
    _key_states: Spool = field(default_factory=lambda: Spool(np.uint8, None))
    _plan_times: list[float] = field(default_factory=list)
    _plans: Spool = field(default_factory=lambda: Spool(np.float32, 4))
    _surface_times: list[float] = field(default_factory=list)
    _surfaces: Spool = field(default_factory=lambda: Spool(np.float32, 3))
    _previous_state: np.ndarray | None = None

    def pose(self, time: float, position: np.ndarray, yaw: float) -> None:
        self._pose_times.append(time)
        self._poses.append(np.array([*position, yaw], dtype=np.float32))

    def map_keyframe(self, time: float, state: npt.NDArray[np.uint8],
                     changed_box: IndexBox | None = None) -> None:
        """Store the voxels whose state changed since the previous keyframe, in C order.

        `changed_box`, when given, holds every voxel that changed since then (an empty box:
        none did), so only it is compared: a keyframe then costs the box, not the grid.
        """
        if self._previous_state is None or changed_box is None:
            flat = state.reshape(-1)
            changed = (np.flatnonzero(flat) if self._previous_state is None
                       else np.flatnonzero(flat != self._previous_state.reshape(-1)))
            self._previous_state = state.copy()
            values = flat[changed]
        else:
            box = changed_box.slices()
            now, before = state[box], self._previous_state[box]
            where = np.nonzero(now != before)  # C order in the box is C order in the grid
            lo = changed_box.lo
            changed = np.ravel_multi_index(
                (where[0] + lo[0], where[1] + lo[1], where[2] + lo[2]), state.shape)
            values = now[where]
            self._previous_state[box] = now
        self._key_times.append(time)
        self._key_indices.append(changed)
        self._key_states.append(values)

    def plan(self, time: float, waypoints: np.ndarray) -> None:
        self._plan_times.append(time)
        self._plans.append(np.asarray(waypoints, dtype=np.float32).reshape(-1, 4))

    def surface(self, time: float, points: np.ndarray, voxel_m: float) -> None:
        """Store the reconstructed surface at `time`, thinned to one point per `voxel_m` cell."""
        self._surface_times.append(time)
        self._surfaces.append(thinned(np.asarray(points), voxel_m))

    def save(self, path: Path) -> None:
        """Write the archive (the format `np.savez_compressed` writes), one array at a time; the
        writer can save again, or be closed."""
        header = {**self.header, "format": FORMAT, "version": VERSION}
        small = {
            "header": np.array(json.dumps(header)),
            "pose_times": np.array(self._pose_times, dtype=np.float64),
            "poses": np.array(self._poses, dtype=np.float32).reshape(-1, 4),
            "keyframe_times": np.array(self._key_times, dtype=np.float64),
            "keyframe_offsets": _offsets(self._key_indices.lengths),
            "plan_times": np.array(self._plan_times, dtype=np.float64),
            "plan_offsets": _offsets(self._plans.lengths),
            "surface_times": np.array(self._surface_times, dtype=np.float64),
            "surface_offsets": _offsets(self._surfaces.lengths),
        }
        flat = {"keyframe_indices": self._key_indices, "keyframe_states": self._key_states,
                "plan_waypoints": self._plans, "surface_points": self._surfaces}
        # Deflate's fastest level: on a large area's surface points and keyframes it takes a
        # third of the default level's time for a file a few percent larger.
        with zipfile.ZipFile(path, mode="w", compression=zipfile.ZIP_DEFLATED,
                             compresslevel=1, allowZip64=True) as archive:
            for name, array in small.items():
                _write_array(archive, name, array)
            for name, spool in flat.items():
                spool.write_npy(archive, name)

    def close(self) -> None:
        """Let go of the sequences' temporary files."""
        for spool in (self._key_indices, self._key_states, self._plans, self._surfaces):
            spool.close()


class Recording:
    """A recording read back from disk."""

    def __init__(self, path: Path) -> None:
        try:
            data = np.load(path, allow_pickle=False)
        except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
            raise RecordingError(f"{path}: not a readable recording ({exc})") from exc
        if not isinstance(data, np.lib.npyio.NpzFile):
            raise RecordingError(f"{path}: not a recording archive")
        try:
            with data:
                self._arrays = {k: data[k] for k in data.files}
        except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as exc:
            raise RecordingError(f"{path}: corrupt recording ({exc})") from exc
        try:
            header = json.loads(str(self._arrays["header"]))
        except (KeyError, json.JSONDecodeError) as exc:
            raise RecordingError(f"{path}: missing or corrupt header") from exc
        if not isinstance(header, dict):
            raise RecordingError(f"{path}: header is not an object")
        self.header: dict[str, Any] = header
        if self.header.get("format") != FORMAT or self.header.get("version") != VERSION:
            raise RecordingError(
                f"{path}: format {self.header.get('format')} v{self.header.get('version')}, "
                f"expected {FORMAT} v{VERSION}"
            )

    def array(self, name: str) -> np.ndarray:
        return self._arrays[name]

    @property
    def pose_times(self) -> np.ndarray:
        return self._arrays["pose_times"]

    @property
    def poses(self) -> np.ndarray:
        """(T, 4) x, y, z, yaw."""
        return self._arrays["poses"]

    def map_state_at(self, time: float) -> npt.NDArray[np.uint8]:
        """(nx, ny, nz) occupancy state as of the last keyframe at or before `time`."""
        shape = tuple(self.header["grid_shape"])
        state = np.zeros(int(np.prod(shape)), dtype=np.uint8)
        times, off = self._arrays["keyframe_times"], self._arrays["keyframe_offsets"]
        idx, val = self._arrays["keyframe_indices"], self._arrays["keyframe_states"]
        last = int(np.searchsorted(times, time, side="right"))
        # Each keyframe's indices are unique; applying them in order reproduces the state.
        for k in range(last):
            state[idx[off[k]: off[k + 1]]] = val[off[k]: off[k + 1]]
        return state.reshape(shape)

    def surface_at(self, time: float) -> np.ndarray:
        """(N, 3) reconstructed surface points of the last snapshot at or before `time`."""
        return self._latest("surface", "surface_points", time, 3)

    def plan_at(self, time: float) -> np.ndarray:
        """(N, 4) waypoints of the last plan made at or before `time`."""
        return self._latest("plan", "plan_waypoints", time, 4)

    def _latest(self, prefix: str, flat: str, time: float, width: int) -> np.ndarray:
        """The last item of a flat sequence stamped at or before `time`; empty before the first."""
        times, off = self._arrays[f"{prefix}_times"], self._arrays[f"{prefix}_offsets"]
        i = int(np.searchsorted(times, time, side="right")) - 1
        if i < 0:
            return np.zeros((0, width), dtype=np.float32)
        return self._arrays[flat][off[i]: off[i + 1]]
