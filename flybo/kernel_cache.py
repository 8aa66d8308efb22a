"""Numba's on-disk kernel cache, dropped whole when any kernel source changes.

Numba keys a cached kernel by the stamp of its own source file only. A kernel that calls a
compiled function of another file (Classic's viewpoint search, in `planners.viewpoints`, runs
`planners.search`'s Dijkstra) keeps the callee as it was compiled after that other file changed:
the process then flies code that is no longer in the tree, which no version lock sees. So the
`__pycache__` of each package with kernels keeps a stamp, the digest of every Python source of
those packages; the `flybo` package, when imported, compares it with the sources and, where it
differs, drops the cached kernels (`*.nbi`, `*.nbc`) of every such package, which then compile
again once. A folder that cannot be written (an installed, read-only package) is left as it is,
and so is a cache numba keeps elsewhere (`NUMBA_CACHE_DIR`, as the planner sandbox sets it: its
kernels are copied from the checked `__pycache__` folders, `worker.sandbox.packages`).
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import tempfile
from collections.abc import Iterable
from pathlib import Path

# The packages whose modules hold numba kernels.
KERNEL_PACKAGES = ("areas", "planners", "sim")
STAMP = "flybo-kernels.stamp"


def kernel_package_dirs() -> list[Path]:
    """The folders of `KERNEL_PACKAGES`, found without importing them (they import numba)."""
    found: list[Path] = []
    for name in KERNEL_PACKAGES:
        try:
            spec = importlib.util.find_spec(name)
        except (ImportError, ValueError):
            continue
        if spec is not None and spec.submodule_search_locations:
            found.extend(Path(p) for p in spec.submodule_search_locations)
    return found


def _sources(roots: Iterable[Path]) -> list[tuple[Path, Path]]:
    """(root, source) for every `*.py` under `roots`, sorted."""
    return [(root, path) for root in sorted(roots) for path in sorted(root.rglob("*.py"))
            if "__pycache__" not in path.parts]


def sources_digest(roots: Iterable[Path]) -> str:
    """SHA-256 of every `*.py` under `roots`: relative paths and contents, in sorted order."""
    return _digest(_sources(roots))


def _digest(sources: list[tuple[Path, Path]]) -> str:
    digest = hashlib.sha256()
    for root, path in sources:
        digest.update(f"{root.name}/{path.relative_to(root).as_posix()}\0".encode())
        digest.update(path.read_bytes())
        digest.update(b"\0")
    return digest.hexdigest()


def _write_atomically(path: Path, text: str) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        with os.fdopen(fd, "w") as out:
            out.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def drop_stale_kernels(roots: list[Path] | None = None) -> int:
    """Drop the cached kernels of the folders under `roots` (default: the kernel packages) whose
    stamp does not name the current sources, and stamp each folder with them (made if need be,
    so that kernels compiled from now on are known to be current); returns how many cache
    files were removed."""
    roots = kernel_package_dirs() if roots is None else roots
    try:
        sources = _sources(roots)
        current = _digest(sources)
        # Every folder holding sources, the packages' own included.
        folders = sorted({path.parent / "__pycache__" for _, path in sources})
    except OSError:
        return 0
    removed = 0
    for folder in folders:
        stamp = folder / STAMP
        try:
            if stamp.is_file() and stamp.read_text().strip() == current:
                continue
            folder.mkdir(parents=True, exist_ok=True)
            for kernel in [*folder.glob("*.nbi"), *folder.glob("*.nbc")]:
                kernel.unlink(missing_ok=True)
                removed += 1
            _write_atomically(stamp, current + "\n")
        except OSError:
            continue  # not ours to write: numba cannot write its kernels there either
    return removed
