"""How the planner process is isolated: namespaces (bubblewrap), cgroups and resource limits.

- **Filesystem**: a new root holding only the system libraries, the Python installation and
  the libraries it imports, the project's simulation and planner packages (read-only), the
  planner's code (read-only), the map file (read-only) and an empty working folder. Ground
  truth, database, broker files, artifacts and other submissions are not in it, nor the
  service's own packages (`server`, `web`, `flybo`), where an installed flybo has them in the
  Python installation's site-packages. The packages are found where Python imports them from:
  a source tree, an editable install or an installed wheel alike.
- **Namespaces**: no network (a new, empty network namespace), own PID, IPC and UTS namespaces,
  an empty environment, a new session; the process dies with the worker.
- **Limits**: processes (cgroup `pids.max`), memory (cgroup memory limit), CPU seconds, open
  files, file size and core dumps (rlimits).
Uploaded code runs only where `probe()` finds all of it (`Isolation.full`): `require_full()`
raises `SandboxUnavailableError` otherwise, so that the upload is refused and the run fails as
the platform's fault. Only an operator's explicit `FLYBO_SANDBOX_ALLOW_INSECURE=1` lets it run
without, in the fallback: the same child with rlimits and, if writable, cgroups, and an audit
hook that is a diagnostic, not a boundary (`docs/sandbox.md`). A failed probe is not cached: the
next sandbox probes again.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib.util
import logging
import os
import resource
import shutil
import site
import subprocess
import sys
import threading
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

from pydantic import BaseModel, Field
from pydantic_settings import BaseSettings, SettingsConfigDict

log = logging.getLogger(__name__)

# The packages the planner process imports; nothing else of the project is visible to it. Not
# `areas`: with its generators a planner could rebuild the scene it is asked to explore.
VISIBLE_PACKAGES = ("sim", "planners", "worker")
HIDDEN_PACKAGES = ("flybo", "server", "web", "areas")
CGROUP_V1 = Path("/sys/fs/cgroup")


class SandboxUnavailableError(RuntimeError):
    """This machine cannot isolate uploaded code (the platform's failure, not the planner's)."""


class SandboxPolicy(BaseSettings):
    """The sandbox's own settings, read like `server.settings.Settings` (`FLYBO_*`)."""

    model_config = SettingsConfigDict(env_prefix="FLYBO_", extra="ignore")

    sandbox_allow_insecure: bool = Field(
        default=False,
        description="run uploaded planners even without full isolation (development only: "
                    "the fallback does not contain hostile code)")


class SandboxLimits(BaseModel):
    """Resource limits of one planner process."""

    memory_mib: int = Field(default=2048, ge=256)
    processes: int = Field(default=64, ge=8, description="threads count too")
    cpu_seconds: int = Field(default=3600, ge=10)
    open_files: int = Field(default=256, ge=32)
    file_size_mib: int = Field(default=64, ge=1)
    start_timeout_s: float = Field(default=60.0, gt=0)
    plan_timeout_s: float = Field(default=10.0, gt=0)
    run_planning_budget_s: float = Field(default=1800.0, gt=0)


@dataclass(frozen=True)
class Isolation:
    """What this machine offers: bubblewrap with namespaces, and which cgroup controllers."""

    bwrap: str | None
    namespaces: bool
    cgroup_pids: Path | None
    cgroup_memory: Path | None
    notes: list[str] = field(default_factory=list)

    @property
    def full(self) -> bool:
        """Bubblewrap with namespaces, and the pids and memory cgroups: what uploaded code
        needs."""
        return bool(self.bwrap and self.namespaces and self.cgroup_pids is not None
                    and self.cgroup_memory is not None)


def _cgroup_root(controller: str) -> Path | None:
    for candidate in (CGROUP_V1 / controller / "flybo-sandbox", CGROUP_V1 / "flybo-sandbox"):
        try:
            candidate.mkdir(parents=True, exist_ok=True)
        except OSError:
            continue
        limit_file = {"pids": "pids.max", "memory": "memory.limit_in_bytes"}[controller]
        if candidate.parent == CGROUP_V1:  # cgroup v2: one hierarchy
            limit_file = {"pids": "pids.max", "memory": "memory.max"}[controller]
            for parent in (CGROUP_V1, candidate):  # the controller must reach our children
                with contextlib.suppress(OSError):
                    (parent / "cgroup.subtree_control").write_text(f"+{controller}")
        probe = candidate / f"probe-{uuid.uuid4().hex[:8]}"
        try:
            probe.mkdir()
            try:
                # Writable, not merely there: a limit that cannot be set is no limit.
                (probe / limit_file).write_text("64" if controller == "pids" else "268435456")
                ok = True
            finally:
                probe.rmdir()
        except OSError:
            ok = False
        if ok:
            return candidate
    return None


# Bubblewrap with the options `command` starts the planner process with.
_PROBE_ARGS = ("--die-with-parent", "--new-session", "--unshare-all", "--uid", "65534", "--gid",
               "65534", "--hostname", "sandbox", "--ro-bind", "/", "/", "--proc", "/proc",
               "--dev", "/dev", "--tmpfs", "/tmp", "--", "true")
_full_isolation: Isolation | None = None


def probe() -> Isolation:
    """What this machine offers. A full result is kept for the process; anything less is probed
    again at the next call (a cgroup or namespace setting may be fixed while the worker runs)."""
    global _full_isolation
    if _full_isolation is not None:
        return _full_isolation
    iso = _probe()
    if iso.full:
        _full_isolation = iso
    return iso


def _probe() -> Isolation:
    notes = []
    bwrap = shutil.which("bwrap")
    namespaces = False
    if bwrap is None:
        notes.append("bubblewrap (bwrap) is not installed: no namespaces")
    else:
        try:
            result = subprocess.run([bwrap, *_PROBE_ARGS], capture_output=True, text=True,
                                    timeout=30)
            namespaces = result.returncode == 0
            why = result.stderr.strip()
        except (OSError, subprocess.SubprocessError) as exc:
            why = str(exc)
        if not namespaces:
            notes.append(f"bubblewrap cannot create namespaces here: {why}")
    pids, memory = _cgroup_root("pids"), _cgroup_root("memory")
    if pids is None:
        notes.append("no writable pids cgroup: the process count is limited by RLIMIT_NPROC "
                     "only, which does not bind root")
    if memory is None:
        notes.append("no writable memory cgroup: memory is limited by RLIMIT_AS")
    return Isolation(bwrap, namespaces, pids, memory, notes)


def insecure_allowed() -> bool:
    """Whether the operator set `FLYBO_SANDBOX_ALLOW_INSECURE`, read at each call."""
    return SandboxPolicy().sandbox_allow_insecure


def require_full(what: str = "uploaded planners") -> Isolation:
    """The probe's result when it is full; else `SandboxUnavailableError`, unless the operator
    allowed the insecure fallback, which is then logged at every use."""
    iso = probe()
    if iso.full:
        return iso
    notes = "; ".join(iso.notes) or "incomplete isolation"
    if insecure_allowed():
        log.error("INSECURE: running %s WITHOUT full isolation because "
                  "FLYBO_SANDBOX_ALLOW_INSECURE is set; hostile code is not contained (%s)",
                  what, notes)
        return iso
    raise SandboxUnavailableError(
        f"the planner sandbox is not available on this machine ({notes}); {what} run only in "
        "bubblewrap with namespaces and the pids and memory cgroups (see docs/sandbox.md)")


@dataclass
class Cgroups:
    """The cgroups of one planner process, removed by `cleanup`."""

    paths: list[Path]
    memory: Path | None

    def oom_killed(self) -> bool:
        if self.memory is None:
            return False
        for name in ("memory.oom_control", "memory.events"):
            path = self.memory / name
            if path.exists():
                for line in path.read_text().splitlines():
                    key, _, value = line.partition(" ")
                    if key == "oom_kill" and value.strip() not in ("", "0"):
                        return True
        failcnt = self.memory / "memory.failcnt"
        return failcnt.exists() and failcnt.read_text().strip() not in ("", "0")

    def cleanup(self, wait_s: float = 2.0) -> None:
        """Kill what is left in the cgroups and remove them. A cgroup stays busy until its
        killed processes are reaped; one still busy after `wait_s` is removed by a later
        `make_cgroups` instead of being left behind."""
        remaining = list(self.paths)
        deadline = time.monotonic() + wait_s
        while True:
            remaining = [path for path in remaining if not _remove_cgroup(path)]
            if not remaining or time.monotonic() >= deadline:
                break
            time.sleep(0.02)
        with _stale_lock:
            _stale_cgroups.extend(remaining)


# Cgroups of this process that were still busy when their sandbox closed.
_stale_cgroups: list[Path] = []
_stale_lock = threading.Lock()


def _remove_cgroup(path: Path) -> bool:
    """Kill the processes in cgroup `path` and remove it; whether it is gone."""
    try:
        for pid in (path / "cgroup.procs").read_text().split():
            with contextlib.suppress(ProcessLookupError, ValueError):
                os.kill(int(pid), 9)
        path.rmdir()
    except FileNotFoundError:
        return True
    except OSError:
        return False
    return True


def make_cgroups(iso: Isolation, limits: SandboxLimits) -> Cgroups:
    with _stale_lock:
        _stale_cgroups[:] = [path for path in _stale_cgroups if not _remove_cgroup(path)]
    name = f"sbx-{uuid.uuid4().hex[:12]}"
    paths: list[Path] = []
    memory: Path | None = None
    if iso.cgroup_pids is not None:
        path = iso.cgroup_pids / name
        path.mkdir()
        (path / "pids.max").write_text(str(limits.processes))
        paths.append(path)
    if iso.cgroup_memory is not None:
        path = iso.cgroup_memory / name
        if not path.exists():
            path.mkdir()
        limit = str(limits.memory_mib * 1024 * 1024)
        for fname in ("memory.limit_in_bytes", "memory.max"):
            if (path / fname).exists():
                (path / fname).write_text(limit)
        swap = path / "memory.memsw.limit_in_bytes"
        if swap.exists():
            with contextlib.suppress(OSError):
                swap.write_text(limit)
        if path not in paths:
            paths.append(path)
        memory = path
    return Cgroups(paths, memory)


def preexec(limits: SandboxLimits, cgroups: Cgroups, iso: Isolation) -> Callable[[], None]:
    """Runs in the forked child before exec: join the cgroups, set the rlimits."""
    targets = [str(p / "cgroup.procs") for p in cgroups.paths]

    def apply() -> None:
        pid = str(os.getpid())
        for target in targets:
            with open(target, "w") as fh:
                fh.write(pid)
        mib = 1024 * 1024
        resource.setrlimit(resource.RLIMIT_CPU, (limits.cpu_seconds, limits.cpu_seconds + 5))
        resource.setrlimit(resource.RLIMIT_NOFILE, (limits.open_files, limits.open_files))
        resource.setrlimit(resource.RLIMIT_FSIZE, (limits.file_size_mib * mib,) * 2)
        resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
        resource.setrlimit(resource.RLIMIT_NPROC, (limits.processes, limits.processes))
        if iso.cgroup_memory is None:
            # Address space, not resident memory: generous, since numba and BLAS reserve a lot.
            space = 4 * limits.memory_mib * mib
            resource.setrlimit(resource.RLIMIT_AS, (space, space))

    return apply


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


def _prefixes() -> list[str]:
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
        if not any(path.is_relative_to(prefix) for prefix in _prefixes()):
            found.append(str(path))
    return found


def _hidden_dirs(bound: list[str]) -> list[str]:
    """The service's own packages where a bound folder would show them (an installed flybo)."""
    hidden = []
    for name in HIDDEN_PACKAGES:
        path = _package_dir(name)
        if path is not None and any(path.is_relative_to(root) for root in bound):
            hidden.append(str(path))
    return hidden


def command(iso: Isolation, *, work: Path, code: Path | None, map_dir: Path,
            child_args: list[str]) -> list[str]:
    """The command line that starts the planner process."""
    python = [sys.executable, "-s", "-B", "-m", "worker.sandbox.child", *child_args]
    if not (iso.bwrap and iso.namespaces):
        return python
    args = [iso.bwrap, "--die-with-parent", "--new-session", "--unshare-all",
            "--uid", "65534", "--gid", "65534", "--hostname", "sandbox",
            "--ro-bind", "/usr", "/usr", "--proc", "/proc", "--dev", "/dev", "--tmpfs", "/tmp"]
    for link in ("bin", "lib", "lib64", "sbin"):
        target = Path("/") / link
        if target.is_symlink():
            args += ["--symlink", os.readlink(target), str(target)]
        elif target.is_dir():
            args += ["--ro-bind", str(target), str(target)]
    libraries = [*_prefixes(), *library_dirs()]
    for folder in libraries:
        args += ["--ro-bind", folder, folder]
    for folder in _hidden_dirs(libraries):
        args += ["--tmpfs", folder]
    for path in package_dirs().values():
        args += ["--ro-bind", str(path), str(path)]
    args += ["--bind", str(work), "/sandbox/work", "--ro-bind", str(map_dir), "/sandbox/map"]
    if code is not None:
        args += ["--ro-bind", str(code), "/sandbox/code"]
    args += ["--chdir", "/sandbox/work", "--clearenv", "--setenv", "HOME", "/sandbox/work",
             "--setenv", "PYTHONPATH", python_path(), "--setenv", "OMP_NUM_THREADS", "1",
             "--setenv", "NUMBA_NUM_THREADS", "1", "--setenv", "OPENBLAS_NUM_THREADS", "1",
             "--setenv", "NUMBA_CACHE_DIR", "/sandbox/work/.numba-cache", "--", *python]
    return args


def seed_numba_cache(work: Path) -> Path:
    """Copy the project's compiled numba kernels into a writable cache in the working folder.

    Numba uses a source folder's `__pycache__` only when it may write there, which the planner
    process may not; without this copy it would compile every kernel again, for seconds, in its
    first planning call. Returns the folder to pass as `NUMBA_CACHE_DIR`.
    """
    cache = work / ".numba-cache"
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
    for path in [cache, *cache.rglob("*")]:
        path.chmod(0o777 if path.is_dir() else 0o666)
    return cache


def child_paths(iso: Isolation, *, work: Path, code: Path | None,
                map_file: Path) -> tuple[str, str | None]:
    """The map file and code folder as the planner process sees them."""
    if iso.bwrap and iso.namespaces:
        return "/sandbox/map/" + map_file.name, "/sandbox/code" if code is not None else None
    return str(map_file), str(code) if code is not None else None
