"""A seccomp filter for the planner process, built with libseccomp (through ctypes) and handed
to bubblewrap (`--seccomp FD`), which loads it just before it starts the planner.

It refuses (EPERM) system calls a planner has no use for that open kernel code to attack or
reach past the namespaces: eBPF, perf events, userfaultfd, io_uring, the kernel keyring,
ptrace and the cross-process memory calls, modules, kexec, mounts, namespaces (`unshare`,
`setns`), file handles and the clock. Everything else is allowed: the filter is a second layer
below the namespaces, cgroups and rlimits, not a whitelist. Where libseccomp is not installed
the probe says so and the planner runs without it.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import errno
import os
from functools import lru_cache

DENIED_SYSCALLS = (
    "bpf", "perf_event_open", "userfaultfd", "io_uring_setup", "io_uring_enter",
    "io_uring_register", "keyctl", "add_key", "request_key", "ptrace", "process_vm_readv",
    "process_vm_writev", "kcmp", "init_module", "finit_module", "delete_module", "kexec_load",
    "kexec_file_load", "mount", "umount2", "pivot_root", "chroot", "move_mount", "open_tree",
    "fsopen", "fsconfig", "fsmount", "fspick", "mount_setattr", "unshare", "setns",
    "open_by_handle_at", "name_to_handle_at", "fanotify_init", "swapon", "swapoff", "reboot",
    "acct", "syslog", "quotactl", "lookup_dcookie", "iopl", "ioperm", "settimeofday",
    "clock_settime", "clock_adjtime", "adjtimex", "vhangup",
)
_SCMP_ACT_ALLOW = 0x7FFF0000
_SCMP_ACT_ERRNO = 0x00050000


class SeccompUnavailableError(RuntimeError):
    """libseccomp is not there, or it could not build the filter."""


def _library() -> ctypes.CDLL:
    name = ctypes.util.find_library("seccomp") or "libseccomp.so.2"
    try:
        lib = ctypes.CDLL(name, use_errno=True)
    except OSError as exc:
        raise SeccompUnavailableError(f"libseccomp is not installed ({exc})") from None
    lib.seccomp_init.restype = ctypes.c_void_p
    lib.seccomp_init.argtypes = [ctypes.c_uint32]
    lib.seccomp_syscall_resolve_name.argtypes = [ctypes.c_char_p]
    lib.seccomp_rule_add.argtypes = [ctypes.c_void_p, ctypes.c_uint32, ctypes.c_int,
                                     ctypes.c_uint]
    lib.seccomp_export_bpf.argtypes = [ctypes.c_void_p, ctypes.c_int]
    lib.seccomp_release.argtypes = [ctypes.c_void_p]
    return lib


@lru_cache(maxsize=1)
def filter_program() -> bytes:
    """The compiled filter (classic BPF, this machine's architecture); built once per process.
    `SeccompUnavailableError` where it cannot be."""
    lib = _library()
    ctx = lib.seccomp_init(_SCMP_ACT_ALLOW)
    if not ctx:
        raise SeccompUnavailableError("seccomp_init failed")
    fd = os.memfd_create("flybo-seccomp")
    try:
        for name in DENIED_SYSCALLS:
            number = lib.seccomp_syscall_resolve_name(name.encode())
            if number < 0:
                continue  # not a system call on this architecture
            if lib.seccomp_rule_add(ctx, _SCMP_ACT_ERRNO | errno.EPERM, number, 0) != 0:
                raise SeccompUnavailableError(f"seccomp_rule_add failed for {name}")
        if lib.seccomp_export_bpf(ctx, fd) != 0:
            raise SeccompUnavailableError("seccomp_export_bpf failed")
        size = os.fstat(fd).st_size
        os.lseek(fd, 0, os.SEEK_SET)
        return os.read(fd, size)
    finally:
        os.close(fd)
        lib.seccomp_release(ctx)


def filter_fd() -> int:
    """A new file descriptor holding the filter at offset 0, for `bwrap --seccomp FD` (which
    reads it once); the caller closes it once bubblewrap has started."""
    program = filter_program()
    fd = os.memfd_create("flybo-seccomp")
    try:
        os.write(fd, program)
        os.lseek(fd, 0, os.SEEK_SET)
    except OSError:
        os.close(fd)
        raise
    return fd
