"""Ground truth computed once when several processes miss the disk cache together.

Two workers starting runs of an area whose ground truth is not cached yet (the first runs of a
suite, a new imported building), or parallel processes of a gymnasium vector environment, would
each compute the same file. `load_ground_truth_once` lets one compute it while the others wait
for its lock and then read the file it wrote.
"""

from __future__ import annotations

import fcntl

from areas.area import Area, GroundTruth
from areas.cache import cache_dir
from areas.ground_truth import ground_truth_path, load_ground_truth


def load_ground_truth_once(area: Area) -> GroundTruth:
    """`load_ground_truth`, holding the area's build lock while the cache may be filled.

    Lock files stay in a folder of their own (removing one would let a third process lock a new
    file while the second still holds the old); the kernel releases a lock when its holder
    exits, even by a crash.
    """
    path = ground_truth_path(area)
    locks = cache_dir() / "locks"
    locks.mkdir(parents=True, exist_ok=True)
    with open(locks / f"{path.parent.name}-{path.stem}.lock", "a+b") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            # From memory or the cache when another process wrote it meanwhile; else computed.
            return load_ground_truth(area)
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)
