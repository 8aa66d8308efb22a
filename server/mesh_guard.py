"""A cheap scan of an uploaded mesh before it is parsed: a face count over the limit, declared
or counted, is refused without loading the mesh into memory."""

from __future__ import annotations

import struct
from pathlib import Path


class MeshGuardError(ValueError):
    pass


def _too_many(count: int, limit: int) -> None:
    if count > limit:
        raise MeshGuardError(f"the mesh has {count} faces, more than the limit of {limit}")


def prescan(path: Path, max_faces: int) -> None:
    """Raise `MeshGuardError` when the file declares or holds more than `max_faces` faces."""
    suffix = path.suffix.lower()
    if suffix == ".obj":
        faces = 0
        with path.open("rb") as fh:
            for line in fh:
                if line.startswith(b"f ") or line.startswith(b"f\t"):
                    faces += 1
        _too_many(faces, max_faces)
    elif suffix == ".ply":
        with path.open("rb") as fh:
            for _ in range(200):
                line = fh.readline(1024).strip()
                if line.startswith(b"element face"):
                    parts = line.split()
                    if len(parts) == 3 and parts[2].isdigit():
                        _too_many(int(parts[2]), max_faces)
                if line == b"end_header" or not line:
                    break
    elif suffix == ".stl":
        with path.open("rb") as fh:
            head = fh.read(84)
        if len(head) == 84 and not head.startswith(b"solid"):
            (count,) = struct.unpack("<I", head[80:84])
            _too_many(count, max_faces)
            if path.stat().st_size != 84 + 50 * count:
                raise MeshGuardError(f"the binary STL declares {count} faces but its size "
                                     "does not match")
    elif suffix == ".off":
        with path.open("rb") as fh:
            numbers: list[bytes] = []
            for _ in range(50):
                line = fh.readline(1024)
                if not line:
                    break
                line = line.split(b"#")[0].strip()
                if not line or line.upper() == b"OFF":
                    continue
                numbers = line.removeprefix(b"OFF").split()
                break
        if len(numbers) >= 2 and numbers[1].isdigit():
            _too_many(int(numbers[1]), max_faces)
