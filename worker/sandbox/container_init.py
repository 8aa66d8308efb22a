"""The container's entry point: make its own cgroups usable by the sandbox, then run the command.

``python -m worker.sandbox.container_init COMMAND...`` (the image's ENTRYPOINT). Docker mounts a
container's ``/sys/fs/cgroup`` read-only; with ``CAP_SYS_ADMIN`` and a private cgroup namespace
(docker-compose.yml) this remounts writable what the sandbox uses, which shows the container's
own subtree only: on cgroup v2 the one hierarchy, on cgroup v1 the pids and memory ones. The
remount changes the mount's own flag (``remount,bind,rw``): a cgroup v1 hierarchy is the
host's file system bound in, whose options the kernel refuses to change ("mount point is busy").
On cgroup v2 a cgroup that hands controllers to its children may hold no process itself, so the
processes of the container's root cgroup move to a leaf, ``init``, and the pids and memory
controllers are enabled for the children, where `worker.sandbox.isolation` makes one cgroup per
planner process. Every step is best effort: what fails is printed, and `isolation.probe()` then
finds the isolation incomplete and refuses uploaded code (`docs/sandbox.md`).
"""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
from pathlib import Path

CGROUP = Path("/sys/fs/cgroup")
CONTROLLERS = ("pids", "memory")


def _cgroup_mounts() -> list[tuple[str, bool]]:
    """(mount point, read-only) of the cgroup file systems the sandbox uses: /sys/fs/cgroup
    itself (v2) and the v1 hierarchies of `CONTROLLERS`."""
    wanted = {str(CGROUP), *(str(CGROUP / controller) for controller in CONTROLLERS)}
    found = []
    with contextlib.suppress(OSError), open("/proc/self/mountinfo") as fh:
        for line in fh:
            fields = line.split()
            if " - " not in line:
                continue
            fstype = line.split(" - ", 1)[1].split()[0]
            point, options = fields[4], fields[5].split(",")
            if fstype in ("cgroup", "cgroup2") and point in wanted:
                found.append((point, "ro" in options))
    return found


def _remount_writable(point: str) -> str | None:
    """Make the mount at `point` writable; why not, if it could not be."""
    errors = []
    # The mount's own flag first; a read-only file system (a cgroup2 mounted ro) needs the
    # plain remount.
    for options in ("remount,bind,rw", "remount,rw"):
        done = subprocess.run(["mount", "-o", options, point], capture_output=True, text=True)
        if done.returncode == 0 and os.access(point, os.W_OK):
            return None
        errors.append(done.stderr.strip().splitlines()[0] if done.stderr.strip()
                      else f"{options}: still read-only")
    return "; ".join(errors)


def prepare() -> list[str]:
    """Set the cgroups up; returns notes on what could not be done."""
    notes = []
    for point, read_only in _cgroup_mounts():
        error = _remount_writable(point) if read_only else None
        if error is not None:
            notes.append(f"cannot remount {point} writable ({error}); the container needs "
                         "CAP_SYS_ADMIN (docker-compose.yml)")
    if (CGROUP / "cgroup.controllers").exists():  # cgroup v2
        leaf = CGROUP / "init"
        try:
            leaf.mkdir(exist_ok=True)
            for pid in (CGROUP / "cgroup.procs").read_text().split():
                with contextlib.suppress(OSError):  # a process may have ended since
                    (leaf / "cgroup.procs").write_text(pid)
            wanted = " ".join(f"+{c}" for c in CONTROLLERS)
            (CGROUP / "cgroup.subtree_control").write_text(wanted)
        except OSError as exc:
            notes.append(f"cannot delegate the {' and '.join(CONTROLLERS)} cgroup controllers: "
                         f"{exc}")
    return notes


def main() -> None:
    command = sys.argv[1:]
    if not command:
        raise SystemExit("usage: python -m worker.sandbox.container_init COMMAND...")
    for note in prepare():
        print(f"flybo sandbox: {note}", file=sys.stderr, flush=True)
    os.execvp(command[0], command)


if __name__ == "__main__":
    main()
