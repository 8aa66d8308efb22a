"""The planner's writable folders are memory of limited size, not the host's disk; it cannot
create user namespaces of its own; the seccomp filter refuses the system calls it lists."""

from __future__ import annotations

import ast
import stat
from dataclasses import replace
from pathlib import Path

import pytest

from sim.episode import run_episode
from tests.sandbox.conftest import required
from tests.sandbox.test_hostile import CONFIG, _planner
from worker.sandbox import isolation
from worker.sandbox.dry_run import tiny_area
from worker.sandbox.isolation import MIN_BWRAP, SandboxLimits, _probe_bwrap, probe
from worker.sandbox.proxy import SandboxedPlanner, SandboxError

# Writes 4 MiB files into each folder (below the file size limit) until a write fails, through
# libc: the audit hook would refuse /dev/shm before the file system does.
FILLS = """
libc = ctypes.CDLL(None, use_errno=True)
found = {}
for folder in ('/tmp', '/sandbox/work', '/dev/shm'):
    written, error, index = 0, None, 0
    while error is None and written < 1024 * 1024 * 1024:
        fd = libc.open(f'{folder}/fill-{index}'.encode(), os.O_WRONLY | os.O_CREAT, 0o644)
        if fd < 0:
            error = os.strerror(ctypes.get_errno())
            break
        try:
            for _ in range(64):
                written += os.write(fd, b'x' * 65536)
        except OSError as exc:
            error = exc.strerror
        os.close(fd)
        index += 1
    found[folder] = (written // (1024 * 1024), error)
raise RuntimeError(repr(found))
"""


def _fly_holding(tmp_path: Path, source: str, limits: SandboxLimits) -> tuple[str, list[Path]]:
    """Fly `source`; the reason it failed, and the files of 1 MiB or more that the sandbox's
    folder on the host held before it was closed."""
    code = tmp_path / "code"
    code.mkdir(parents=True)
    (code / "planner.py").write_text(source)
    area, truth = tiny_area()
    with SandboxedPlanner(code=code, limits=limits) as planner:
        try:
            result = run_episode(area, truth, planner, CONFIG, 0, seconds=4.0)
            reason = result.reason
        except SandboxError as exc:
            reason = str(exc)
        large = [path for path in planner.tmp.rglob("*")
                 if path.is_file() and path.stat().st_size >= 1024 * 1024]
    return reason, large


def test_filling_the_writable_folders_ends_in_enospc(tmp_path: Path, isolated: None) -> None:
    limits = SandboxLimits(scratch_mib=32, plan_timeout_s=8.0, memory_mib=1024)
    reason, large = _fly_holding(tmp_path, _planner(FILLS), limits)
    assert "RuntimeError" in reason, reason
    found = ast.literal_eval(reason[reason.index("{"):reason.rindex("}") + 1])
    for folder in ("/tmp", "/sandbox/work", "/dev/shm"):
        mib, error = found[folder]
        assert error == "No space left on device", (folder, found)
        assert mib <= limits.scratch_mib, (folder, found)
    # Nothing of it reached the host: its working folder there holds no filled files.
    assert not any(path.name.startswith("fill-") for path in large), large
    assert not list(Path("/tmp").glob("fill-*"))


NESTS = """
libc = ctypes.CDLL(None, use_errno=True)
CLONE_NEWUSER = 0x10000000
result = libc.unshare(CLONE_NEWUSER)
error = os.strerror(ctypes.get_errno()) if result != 0 else None
raise RuntimeError(f'unshare gave {result} ({error})')
"""


def test_a_planner_cannot_create_a_user_namespace(tmp_path: Path, isolated: None,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    reason, _ = _fly_holding(tmp_path / "filtered", _planner(NESTS), SandboxLimits())
    assert "unshare gave -1" in reason, reason
    # Without the seccomp filter too: the user namespace allows no nested one
    # (`--disable-userns`), which the kernel reports as ENOSPC.
    iso = replace(probe(), seccomp=False)
    monkeypatch.setattr(isolation, "probe", lambda: iso)
    reason, _ = _fly_holding(tmp_path / "unfiltered", _planner(NESTS), SandboxLimits())
    assert "unshare gave -1 (No space left on device)" in reason, reason


# Calls that succeed for any process without the filter: unshare of nothing, asking to be traced
# by its parent, a tmpfs mounted in its own mount namespace (its user namespace's root may),
# asking for its keyring's id; and bpf, which the filter refuses before the kernel looks at it.
FILTERED = """
libc = ctypes.CDLL(None, use_errno=True)
libc.syscall.restype = ctypes.c_long
found = {}
KEYCTL_GET_KEYRING_ID, KEY_SPEC_PROCESS_KEYRING, SYS_BPF, SYS_KEYCTL = 0, -2, 321, 250  # x86-64
for name, call in (('unshare', lambda: libc.unshare(0)),
                   ('ptrace', lambda: libc.ptrace(0, 0, None, None)),
                   ('mount', lambda: libc.mount(b'none', b'/sandbox/work', b'tmpfs', 0, None)),
                   ('keyctl', lambda: libc.syscall(SYS_KEYCTL, KEYCTL_GET_KEYRING_ID,
                                                   KEY_SPEC_PROCESS_KEYRING, 1)),
                   ('bpf', lambda: libc.syscall(SYS_BPF, 0, None, 0))):
    result = call()
    found[name] = (result, os.strerror(ctypes.get_errno()) if result != 0 else None)
raise RuntimeError(repr(found))
"""


def test_the_seccomp_filter_refuses_its_calls(tmp_path: Path, isolated: None) -> None:
    if not probe().seccomp:
        required(f"no seccomp filter here: {'; '.join(probe().notes)}")
    reason, _ = _fly_holding(tmp_path, _planner(FILTERED), SandboxLimits())
    found = ast.literal_eval(reason[reason.index("{"):reason.rindex("}") + 1])
    refused = (-1, "Operation not permitted")
    assert found == dict.fromkeys(("unshare", "ptrace", "mount", "keyctl", "bpf"), refused), found


def test_an_old_bubblewrap_is_not_full_isolation(tmp_path: Path) -> None:
    old = tmp_path / "bwrap"
    old.write_text("#!/bin/sh\necho bubblewrap 0.6.1\n")
    old.chmod(old.stat().st_mode | stat.S_IXUSR)
    works, note = _probe_bwrap(str(old))
    assert not works
    assert note is not None and "0.6.1 is older than" in note and "--disable-userns" in note
    assert MIN_BWRAP == (0, 8)
