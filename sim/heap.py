"""Giving freed heap memory back to the system, so that a run's resident set is what it holds.

A run frees large NumPy temporaries every frame (rays, voxel lists, surface snapshots). glibc's
allocator raises its mmap threshold after the first large block is freed (up to 32 MiB), so
later blocks of that size come from the heap, and freed heap pages in the middle of it stay
resident: about 400 MiB of a FACILITY C run's resident set belonged to no live array
(`docs/notes/2026-12-run-memory.md`). `malloc_trim(0)` returns every free page of every arena
(glibc 2.8 and later, by `madvise`); it changes no value the run computes.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
from collections.abc import Callable


@functools.cache
def _malloc_trim() -> Callable[[int], int] | None:
    name = ctypes.util.find_library("c")
    if name is None:
        return None
    try:
        libc = ctypes.CDLL(name)
        trim = libc.malloc_trim
    except (OSError, AttributeError):  # not glibc (musl, macOS): nothing to return
        return None
    trim.argtypes = [ctypes.c_size_t]
    trim.restype = ctypes.c_int
    return trim


def release_free_heap() -> bool:
    """Return the allocator's free pages to the system; False where the C library cannot."""
    trim = _malloc_trim()
    if trim is None:
        return False
    trim(0)
    return True
