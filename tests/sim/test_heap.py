"""sim/heap.py: freed heap pages go back to the system, and nothing else changes."""

from __future__ import annotations

import platform
from pathlib import Path

import numpy as np
import pytest

from sim.heap import release_free_heap


def _resident_mib() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    raise AssertionError("no VmRSS in /proc/self/status")


@pytest.mark.skipif(platform.system() != "Linux" or platform.libc_ver()[0] != "glibc",
                    reason="malloc_trim is glibc's; elsewhere release_free_heap does nothing")
def test_freed_blocks_below_the_top_of_the_heap_are_returned() -> None:
    # 100 KiB blocks come from the heap (glibc maps blocks of 128 KiB and more on their own).
    # The last one stays alive, so the heap's top cannot shrink: only a trim of the free
    # blocks below it returns their pages.
    blocks = [np.ones(100 * 1024 // 8) for _ in range(2000)]
    keep = blocks[-1]
    del blocks
    before = _resident_mib()
    assert release_free_heap() is True
    after = _resident_mib()
    assert before - after > 100.0, (before, after)
    assert keep.sum() == len(keep)  # what is alive is untouched


def test_a_second_release_is_harmless() -> None:
    data = np.arange(1000.0)
    release_free_heap()
    release_free_heap()
    assert data.sum() == 499500.0
