"""What of the Python installation and the project the planner process sees: the folders of the
packages it imports, the libraries they need, the service's own packages to hide, and the
compiled numba kernels it starts with."""

from __future__ import annotations

import hashlib
import importlib.util
import os
import shutil
import site
import sys
from functools import lru_cache
from pathlib import Path

# The packages the planner process imports; nothing else of the project is visible to it. Not
# `areas`: with its generators a planner could rebuild the scene it is asked to explore.
VISIBLE_PACKAGES = ("sim", "planners", "worker")
HIDDEN_PACKAGES = ("flybo", "server", "web", "areas")


def _package_dir(name: str) -> Path | None:
    """The folder of top-level package `name` as Python would import it (not importing it)."""
    try:
        spec = importlib.util.find_spec(name)
    except (ImportError, ValueError):
        return None
    if spec is None:
        return None
    if spec.submodule_search_locations:
        return Path(next(iter(spec.submodule_search_locations))).resolve()
    return Path(spec.origin).resolve().parent if spec.origin else None


@lru_cache(maxsize=1)
def package_dirs() -> dict[str, Path]:
    """The folders of the packages the planner process sees: in the source tree, or in
    site-packages once flybo is installed."""
    found = {name: _package_dir(name) for name in VISIBLE_PACKAGES}
    missing = [name for name, path in found.items() if path is None]
    if missing:
        raise RuntimeError(f"cannot find the package(s) {', '.join(missing)}")
    return {name: path for name, path in found.items() if path is not None}


def python_path() -> str:
    """`PYTHONPATH` of the planner process: the folders holding the visible packages."""
    roots = dict.fromkeys(str(path.parent) for path in package_dirs().values())
    return os.pathsep.join(roots)


def prefixes() -> list[str]:
    return sorted({sys.base_prefix, sys.prefix})


def library_dirs() -> list[str]:
    """Site-packages folders on `sys.path` outside the Python installation (added by a `.pth`
    file or `PYTHONPATH`): the planner process needs the libraries found there too. The user's
    own site-packages is left out; the planner process runs without it (`python -s`)."""
    user_site = site.getusersitepackages() if site.ENABLE_USER_SITE else None
    found: list[str] = []
    for entry in sys.path:
        path = Path(entry or ".").resolve()
        if (path.name not in ("site-packages", "dist-packages") or not path.is_dir()
                or str(path) == user_site or str(path) in found):
            continue
        if not any(path.is_relative_to(prefix) for prefix in prefixes()):
            found.append(str(path))
    return found


def hidden_dirs(bound: list[str]) -> list[str]:
    """The service's own packages where a bound folder would show them (an installed flybo)."""
    hidden = []
    for name in HIDDEN_PACKAGES:
        path = _package_dir(name)
        if path is not None and any(path.is_relative_to(root) for root in bound):
            hidden.append(str(path))
    return hidden


def seed_numba_cache(folder: Path) -> Path:
    """Copy the project's compiled numba kernels into `folder` (returned), which the planner
    process copies into its writable `NUMBA_CACHE_DIR` as it starts (`child.seed_cache`).

    Numba uses a source folder's `__pycache__` only when it may write there, which the planner
    process may not; without this copy it would compile every kernel again, for seconds, in its
    first planning call.
    """
    cache = folder
    for package_dir in package_dirs().values():
        for pycache in package_dir.rglob("__pycache__"):
            kernels = list(pycache.glob("*.nb[ic]"))
            if not kernels:
                continue
            source_dir = str(pycache.parent)
            digest = hashlib.sha1(source_dir.encode()).hexdigest()  # numba's own layout
            target = cache / f"{pycache.parent.name}_{digest}"
            target.mkdir(parents=True, exist_ok=True)
            for kernel in kernels:
                shutil.copyfile(kernel, target / kernel.name)
    cache.mkdir(parents=True, exist_ok=True)
    for path in [cache, *cache.rglob("*")]:
        path.chmod(0o755 if path.is_dir() else 0o644)  # read by the sandbox's unprivileged user
    return cache
