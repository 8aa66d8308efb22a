"""Compile the numba kernels into their on-disk cache before the test processes start.

Numba compiles a kernel on its first call and keeps the machine code in the source folder's
`__pycache__` (`cache=True`). On a fresh checkout every test process would otherwise compile
the same kernels at once, for tens of seconds each, and so would every sandboxed planner
(`worker/sandbox/packages.py` seeds the sandbox from that cache). `make test` runs this beside
mypy: every registered planner flies MAZE for 15 s on the default preset, which calls the
simulator's, the ground truth's and every planner's kernels (the exact preset calls them with
the same types). A kernel first called later in a long flight is still compiled by the test
that calls it; nothing here is checked.

    .venv/bin/python tests/warm_kernels.py [--seconds S]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import flybo  # noqa: F401  before NumPy loads: it pins the CPU kernels

SECONDS = 15.0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=SECONDS,
                        help=f"simulated seconds per flight (default {SECONDS:g})")
    args = parser.parse_args(argv)

    from areas import load_area, load_ground_truth
    from planners.registry import make, planner_ids
    from sim.config import preset
    from sim.episode import run_episode

    started = time.monotonic()
    area = load_area("maze")
    truth = load_ground_truth(area)
    for planner_id in planner_ids():
        run_episode(area, truth, make(planner_id), preset("default"), 0,
                    planner_name=planner_id, preset_name="default", seconds=args.seconds)
    print(f"numba kernels compiled and cached in {time.monotonic() - started:.0f} s")
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    sys.exit(main())
