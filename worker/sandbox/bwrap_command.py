"""The bubblewrap command line of the planner process: its namespaces, its new root and its
size-limited writable folders, and the paths it is given as it sees them."""

from __future__ import annotations

import os
import sys
from pathlib import Path

from worker.sandbox.isolation_level import Isolation
from worker.sandbox.limits import SandboxLimits
from worker.sandbox.packages import hidden_dirs, library_dirs, package_dirs, prefixes, python_path

# The working folder and the numba seed as the planner process sees them.
SANDBOX_WORK = "/sandbox/work"
NUMBA_SEED = "/sandbox/numba-seed"

# The namespaces, the new session and the unprivileged user of the planner process. A user
# namespace of its own, explicitly (`--unshare-all` only tries one), and none below it: a
# nested user namespace would hand the planner the kernel code that only root reaches.
NAMESPACE_ARGS = ("--die-with-parent", "--new-session", "--unshare-all", "--unshare-user",
                  "--disable-userns", "--uid", "65534", "--gid", "65534", "--hostname", "sandbox")
# `--disable-userns` came with bubblewrap 0.8.
MIN_BWRAP = (0, 8)
MIB = 1024 * 1024


def scratch_args(limits: SandboxLimits, folder: str) -> list[str]:
    """A writable tmpfs at `folder` of at most `limits.scratch_mib`: a planner that fills it
    gets ENOSPC, and the host's disk is not touched."""
    return ["--size", str(limits.scratch_mib * MIB), "--tmpfs", folder]


def device_args(limits: SandboxLimits) -> list[str]:
    """A new `/dev` holding the usual devices, read-only but for a limited `/dev/shm`."""
    return ["--dev", "/dev", *scratch_args(limits, "/dev/shm"), "--remount-ro", "/dev"]


# Bubblewrap with the options `command` starts the planner process with.
PROBE_ARGS = (*NAMESPACE_ARGS, "--ro-bind", "/", "/", "--proc", "/proc",
              *device_args(SandboxLimits()), *scratch_args(SandboxLimits(), "/tmp"),
              "--", "true")


def seccomp_args(fd: int | None) -> list[str]:
    """Bubblewrap's options loading the seccomp filter in `fd` (`seccomp_filter.filter_fd`)."""
    return [] if fd is None else ["--seccomp", str(fd)]


def command(iso: Isolation, limits: SandboxLimits, *, numba_seed: Path, code: Path | None,
            map_dir: Path, child_args: list[str], seccomp_fd: int | None = None) -> list[str]:
    """The command line that starts the planner process; `seccomp_fd` holds the seccomp
    filter, to be passed to the process."""
    python = [sys.executable, "-s", "-B", "-m", "worker.sandbox.child", *child_args]
    if not (iso.bwrap and iso.namespaces):
        return python
    args = [iso.bwrap, *NAMESPACE_ARGS, *seccomp_args(seccomp_fd), "--ro-bind", "/usr", "/usr",
            "--proc", "/proc", *device_args(limits), *scratch_args(limits, "/tmp")]
    for link in ("bin", "lib", "lib64", "sbin"):
        target = Path("/") / link
        if target.is_symlink():
            args += ["--symlink", os.readlink(target), str(target)]
        elif target.is_dir():
            args += ["--ro-bind", str(target), str(target)]
    libraries = [*prefixes(), *library_dirs()]
    for folder in libraries:
        args += ["--ro-bind", folder, folder]
    for folder in hidden_dirs(libraries):
        args += ["--tmpfs", folder, "--remount-ro", folder]
    for path in package_dirs().values():
        args += ["--ro-bind", str(path), str(path)]
    # The working folder is memory of limited size too, not a folder on the host's disk.
    args += [*scratch_args(limits, SANDBOX_WORK), "--ro-bind", str(numba_seed), NUMBA_SEED,
             "--ro-bind", str(map_dir), "/sandbox/map"]
    if code is not None:
        args += ["--ro-bind", str(code), "/sandbox/code"]
    args += ["--chdir", SANDBOX_WORK, "--clearenv", "--setenv", "HOME", SANDBOX_WORK,
             "--setenv", "PYTHONPATH", python_path(), "--setenv", "OMP_NUM_THREADS", "1",
             "--setenv", "NUMBA_NUM_THREADS", "1", "--setenv", "OPENBLAS_NUM_THREADS", "1",
             "--setenv", "NUMBA_CACHE_DIR", f"{SANDBOX_WORK}/.numba-cache"]
    for name, value in _passed_on().items():
        args += ["--setenv", name, value]
    return [*args, "--", *python]


def child_paths(iso: Isolation, *, numba_seed: Path, code: Path | None,
                map_file: Path) -> tuple[str, str, str | None]:
    """The map file, the numba seed and the code folder as the planner process sees them."""
    if iso.bwrap and iso.namespaces:
        return ("/sandbox/map/" + map_file.name, NUMBA_SEED,
                "/sandbox/code" if code is not None else None)
    return str(map_file), str(numba_seed), str(code) if code is not None else None


def host_environment(work: Path) -> dict[str, str]:
    """The planner process's environment where it runs without bubblewrap (built-in planners,
    the insecure fallback), its working folder `work` on the host; with bubblewrap, `command`
    replaces it (`--clearenv`)."""
    return {"PATH": "/usr/bin:/bin", "HOME": str(work), "PYTHONPATH": python_path(),
            "OMP_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
            "NUMBA_CACHE_DIR": str(work / ".numba-cache"), **_passed_on()}


def _passed_on() -> dict[str, str]:
    """What the planner process takes from the worker's environment: the OpenBLAS kernels and
    NumPy's SIMD loops the worker's entry point chose (`flybo.cpu_kernels`), so that a planner
    computes as in process."""
    names = ("OPENBLAS_CORETYPE", "NPY_DISABLE_CPU_FEATURES")
    return {name: os.environ[name] for name in names if os.environ.get(name)}
