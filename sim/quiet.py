"""Silencing what native libraries print straight to the process's stdout and stderr."""

from __future__ import annotations

import contextlib
import ctypes
import os
import sys
from collections.abc import Iterator

_LIBC = ctypes.CDLL("libc.so.6")


@contextlib.contextmanager
def quiet_native_output() -> Iterator[None]:
    """Send file descriptors 1 and 2 to /dev/null for the duration, C-level prints included."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    try:
        with open(os.devnull, "w") as devnull:
            os.dup2(devnull.fileno(), 1)
            os.dup2(devnull.fileno(), 2)
            yield
    finally:
        _LIBC.fflush(None)  # drop what C stdio buffered while the descriptors were muted
        for fd, copy in ((1, saved[0]), (2, saved[1])):
            os.dup2(copy, fd)
            os.close(copy)
