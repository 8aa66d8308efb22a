"""Imported (custom) areas saved on disk, so that `flybo run --area NAME` finds them later.

One `.npz` file per area in a folder: the mesh, bounds, start pose, plateau time, voxel size
and Table 1 statistics. Written atomically; the name is the file's stem.

Every function takes the folder (`folder=`); without one it is `areas_dir()`, the default
that the area registry and `flybo run` use. The service passes its own (`Settings.areas_dir`,
which is the same folder unless the settings name another data folder).
"""

from __future__ import annotations

import json
import os
import re
import tempfile
import zipfile
from dataclasses import asdict
from pathlib import Path

import numpy as np

from areas.area import Area, AreaInfo, StartPose

DATA_ENV = "FLYBO_DATA_DIR"
FORMAT = "flybo-area"
VERSION = 1
NAME_PATTERN = re.compile(r"^[a-z0-9][a-z0-9-]{0,39}$")


class AreaStoreError(ValueError):
    """A stored area is missing, unreadable, or cannot be saved under that name."""


def areas_dir() -> Path:
    """``$FLYBO_DATA_DIR/areas`` if the variable is set, else ``~/.local/share/flybo/areas``:
    the rule of the service's `server.settings.Settings.areas_dir` (which this layer does not
    import)."""
    configured = os.environ.get(DATA_ENV)
    root = Path(configured).expanduser() if configured else Path.home() / ".local/share/flybo"
    return root / "areas"


def stored_area_names(folder: Path | None = None) -> list[str]:
    """Names of the areas saved in `folder` (default `areas_dir()`), sorted."""
    folder = folder or areas_dir()
    if not folder.is_dir():
        return []
    return sorted(p.stem for p in folder.glob("*.npz") if NAME_PATTERN.match(p.stem))


def save_area(area: Area, *, overwrite: bool = False, folder: Path | None = None) -> Path:
    """Save `area` under its name in `folder` (default `areas_dir()`); refuses to replace an
    existing one unless `overwrite`."""
    if not NAME_PATTERN.match(area.name):
        raise AreaStoreError(
            f"invalid area name {area.name!r}: 1-40 lower-case letters, digits and hyphens"
        )
    folder = folder or areas_dir()
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{area.name}.npz"
    if path.exists() and not overwrite:
        raise AreaStoreError(f"an area named {area.name!r} already exists ({path})")
    header = {
        "format": FORMAT, "version": VERSION, "name": area.name, "plateau_s": area.plateau_s,
        "voxel_size": area.voxel_size, "start_yaw": area.start.yaw, "info": asdict(area.info),
    }
    fd, tmp = tempfile.mkstemp(prefix=f".{area.name}.", suffix=".npz", dir=folder)
    try:
        with os.fdopen(fd, "wb") as fh:
            np.savez_compressed(
                fh, header=np.array(json.dumps(header)), vertices=area.vertices,
                triangles=area.triangles, bounds_min=area.bounds_min,
                bounds_max=area.bounds_max, start_position=area.start.position,
            )
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def load_stored_area(name: str, folder: Path | None = None) -> Area:
    """The area called `name` saved in `folder` (default `areas_dir()`)."""
    folder = folder or areas_dir()
    path = folder / f"{name}.npz"
    if not NAME_PATTERN.match(name) or not path.is_file():
        raise AreaStoreError(f"no stored area named {name!r} in {folder}")
    try:
        with np.load(path, allow_pickle=False) as data:
            header = json.loads(str(data["header"]))
            if header.get("format") != FORMAT or header.get("version") != VERSION:
                raise AreaStoreError(f"{path}: not a {FORMAT} v{VERSION} file")
            return Area(
                name=header["name"],
                vertices=np.asarray(data["vertices"], dtype=np.float64),
                triangles=np.asarray(data["triangles"], dtype=np.int32),
                bounds_min=np.asarray(data["bounds_min"], dtype=np.float64),
                bounds_max=np.asarray(data["bounds_max"], dtype=np.float64),
                start=StartPose(np.asarray(data["start_position"], dtype=np.float64),
                                float(header["start_yaw"])),
                plateau_s=float(header["plateau_s"]),
                voxel_size=float(header["voxel_size"]),
                info=AreaInfo(**header["info"]),
            )
    except (OSError, KeyError, TypeError, ValueError, zipfile.BadZipFile) as exc:
        if isinstance(exc, AreaStoreError):
            raise
        raise AreaStoreError(f"{path}: unreadable stored area ({exc})") from exc
