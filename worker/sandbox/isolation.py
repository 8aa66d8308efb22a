"""How the planner process is isolated: namespaces (bubblewrap), cgroups and resource limits.

- **Filesystem**: a new root holding only the system libraries, the Python installation and
  the libraries it imports, the project's simulation and planner packages (read-only), the
  planner's code (read-only), the map file (read-only) and an empty working folder; the only
  writable folders (work, /tmp, /dev/shm) are tmpfs of limited size, never the host's disk. Ground
  truth, database, broker files, artifacts and other submissions are not in it, nor the
  service's own packages (`server`, `web`, `flybo`), where an installed flybo has them in the
  Python installation's site-packages. The packages are found where Python imports them from:
  a source tree, an editable install or an installed wheel alike.
- **Namespaces**: no network (a new, empty network namespace), own user, PID, IPC and UTS
  namespaces and no further user namespaces (bubblewrap 0.8's `--disable-userns`), an empty
  environment, a new session; the process dies with the worker. A seccomp filter
  (`seccomp_filter`) where libseccomp is installed.
- **Limits**: processes (cgroup `pids.max`), memory (cgroup memory limit), CPU seconds, open
  files, file size and core dumps (rlimits).
Uploaded code runs only where `probe()` finds all of it (`Isolation.full`): `require_full()`
raises `SandboxUnavailableError` otherwise, so that the upload is refused and the run fails as
the platform's fault. Only an operator's explicit `FLYBO_SANDBOX_ALLOW_INSECURE=1` lets it run
without, in the fallback: the same child with rlimits and, if writable, cgroups, and an audit
hook that is a diagnostic, not a boundary (`docs/sandbox.md`); with `FLYBO_ENVIRONMENT=production`
that setting is refused (`SandboxPolicyError`). A failed probe is not cached: the next sandbox
probes again.

This module probes and decides; the parts are `bwrap_command` (the command line), `packages`
(what the planner process sees), `cgroups`, `limits` (rlimits) and `seccomp_filter`, the first
four re-exported here.
"""

from __future__ import annotations

import logging
import os
import shutil
import subprocess
import threading

from pydantic import ValidationError

from server import planner_package
from server.settings import load_settings
from worker.sandbox import seccomp_filter

# Re-exported: the sandbox's parts, as the rest of the project has always imported them.
from worker.sandbox.bwrap_command import (
    MIN_BWRAP,
    NAMESPACE_ARGS,
    PROBE_ARGS,
    child_paths,
    command,
    scratch_args,
    seccomp_args,
)
from worker.sandbox.cgroups import Cgroups, cgroup_root, make_cgroups, preexec, sweep_stale
from worker.sandbox.isolation_level import Isolation
from worker.sandbox.limits import SandboxLimits
from worker.sandbox.packages import (
    HIDDEN_PACKAGES,
    VISIBLE_PACKAGES,
    library_dirs,
    package_dirs,
    python_path,
    seed_numba_cache,
)

__all__ = ["HIDDEN_PACKAGES", "MIN_BWRAP", "NAMESPACE_ARGS", "VISIBLE_PACKAGES", "Cgroups",
           "Isolation", "SandboxLimits", "SandboxPolicyError",
           "SandboxUnavailableError", "child_paths", "command", "insecure_allowed",
           "library_dirs", "make_cgroups", "package_dirs", "preexec", "probe",
           "probe_in_background", "python_path",
           "require_full", "scratch_args", "seed_numba_cache"]

log = logging.getLogger(__name__)


class SandboxUnavailableError(RuntimeError):
    """This machine cannot isolate uploaded code (the platform's failure, not the planner's)."""


class SandboxPolicyError(SandboxUnavailableError, planner_package.SandboxPolicyError):
    """The insecure fallback is set where it is refused: uploaded code does not run."""


_full_isolation: Isolation | None = None
_probe_lock = threading.Lock()


def probe() -> Isolation:
    """What this machine offers. A full result is kept for the process; anything less is probed
    again at the next call (a cgroup or namespace setting may be fixed while the worker runs).
    The first full result also sweeps the cgroups that processes now gone left behind."""
    global _full_isolation
    if _full_isolation is not None:
        return _full_isolation
    with _probe_lock:  # one probe at a time: a burst of uploads at start-up probes once
        if _full_isolation is not None:
            return _full_isolation
        iso = _probe()
        if iso.full:
            swept = sweep_stale(iso)
            if swept:
                log.warning("removed %d planner cgroups left by processes that are gone: %s",
                            len(swept), ", ".join(map(str, swept)))
            _full_isolation = iso
    return iso


def probe_in_background() -> threading.Thread:
    """Probe (and sweep stale cgroups) in a thread as a process starts, so that the first
    upload or run finds the result ready."""
    thread = threading.Thread(target=_probe_quietly, name="sandbox-probe", daemon=True)
    thread.start()
    return thread


def _probe_quietly() -> None:
    try:
        iso = probe()
    except Exception:  # a thread's failure must not go unseen, nor stop the process
        log.exception("probing the planner sandbox failed")
        return
    if not iso.full:
        log.warning("the planner sandbox is incomplete here, uploaded planners are refused: %s",
                    "; ".join(iso.notes))


def _probe() -> Isolation:
    notes = []
    bwrap = shutil.which("bwrap")
    namespaces = False
    try:
        seccomp_filter.filter_program()
        seccomp = True
    except (seccomp_filter.SeccompUnavailableError, OSError) as exc:
        seccomp = False
        notes.append(f"no seccomp filter: {exc}")
    if bwrap is None:
        notes.append("bubblewrap (bwrap) is not installed: no namespaces")
    else:
        namespaces, note = _probe_bwrap(bwrap, seccomp=seccomp)
        if note:
            notes.append(note)
    pids, memory = cgroup_root("pids"), cgroup_root("memory")
    if pids is None:
        notes.append("no writable pids cgroup: the process count is limited by RLIMIT_NPROC "
                     "only, which does not bind root")
    if memory is None:
        notes.append("no writable memory cgroup: memory is limited by RLIMIT_AS")
    return Isolation(bwrap, namespaces, pids, memory, notes, seccomp=namespaces and seccomp)


def bwrap_version(bwrap: str) -> tuple[int, ...] | None:
    """The version `bwrap --version` reports ("bubblewrap 0.8.0"), or None."""
    try:
        result = subprocess.run([bwrap, "--version"], capture_output=True, text=True,
                                timeout=30)
    except (OSError, subprocess.SubprocessError):
        return None
    words = result.stdout.split()
    try:
        return tuple(int(part) for part in words[-1].split(".")) if words else None
    except ValueError:
        return None


def _probe_bwrap(bwrap: str, *, seccomp: bool = False) -> tuple[bool, str | None]:
    """Whether bubblewrap starts a process with the planner's options (and the seccomp filter,
    when `seccomp`); else why not."""
    version = bwrap_version(bwrap)
    if version is None or version < MIN_BWRAP:
        shown = ".".join(map(str, version)) if version else "of unknown version"
        return False, (f"bubblewrap {shown} is older than "
                       f"{'.'.join(map(str, MIN_BWRAP))}: it cannot keep the planner from "
                       "creating user namespaces (--disable-userns)")
    fds = (seccomp_filter.filter_fd(),) if seccomp else ()
    try:
        result = subprocess.run([bwrap, *seccomp_args(fds[0] if fds else None), *PROBE_ARGS],
                                capture_output=True, text=True, timeout=30, pass_fds=fds)
    except (OSError, subprocess.SubprocessError) as exc:
        return False, f"bubblewrap cannot create namespaces here: {exc}"
    finally:
        for fd in fds:
            os.close(fd)
    if result.returncode != 0:
        return False, f"bubblewrap cannot create namespaces here: {result.stderr.strip()}"
    return True, None


def insecure_allowed() -> bool:
    """Whether the operator set `FLYBO_SANDBOX_ALLOW_INSECURE`, read at each call;
    `SandboxPolicyError` where that is refused (`FLYBO_ENVIRONMENT=production`)."""
    try:
        settings = load_settings()
    except ValidationError as exc:
        # Settings that would not let the service start (the fallback in production, say):
        # nothing uploaded runs under them.
        problems = "; ".join(str(e.get("msg", "invalid")) for e in exc.errors())
        raise SandboxPolicyError(f"the service's settings are refused: {problems}") from None
    return settings.sandbox_allow_insecure


def require_full(what: str = "uploaded planners") -> Isolation:
    """The probe's result when it is full; else `SandboxUnavailableError`, unless the operator
    allowed the insecure fallback, which is then logged at every use."""
    insecure = insecure_allowed()  # refused in production even where it is not needed
    iso = probe()
    if iso.full:
        return iso
    notes = "; ".join(iso.notes) or "incomplete isolation"
    if insecure:
        log.error("INSECURE: running %s WITHOUT full isolation because "
                  "FLYBO_SANDBOX_ALLOW_INSECURE is set; hostile code is not contained (%s)",
                  what, notes)
        return iso
    raise SandboxUnavailableError(
        f"the planner sandbox is not available on this machine ({notes}); {what} run only in "
        "bubblewrap with namespaces and the pids and memory cgroups (see docs/sandbox.md)")
