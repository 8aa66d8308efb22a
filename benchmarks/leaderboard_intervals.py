"""What the bootstrap intervals and tie groups cost a leaderboard of the full suite's size.

Synthetic results of the full suite's shape (7 planners x 11 areas x 5 runs, each with its
metrics block; no simulation runs, no series: the board does not read them) in a fresh SQLite
file; `compute_leaderboard` is timed several
times, and within it the time spent in `server.board_statistics` (`describe` for every cell's
intervals, `annotate` for the tie groups and the intervals over areas), measured in the same
calls. Times are CPU time of this process (`time.process_time`), so that other work on the
machine does not count. The board is computed once per change of the results and then served
from the cache, so this is what the first request after a change pays on top.

Run: `.venv/bin/python benchmarks/leaderboard_intervals.py [--repeats 5]`.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import print_table, write_json

PLATEAUS = (700, 600, 750, 1650, 700, 750, 1650, 900, 550, 1200, 1800)
VERSION = "synthetic"


def fill(url: str, planners: int = 7, runs: int = 5) -> int:
    """Write the synthetic results; returns the number of runs."""
    import numpy as np

    from server.db import make_engine, make_session_factory, session_scope
    from server.migrate import upgrade
    from server.models import AreaRow, Job, PlannerRow, Run, RunResult, RunState, User

    rng = np.random.default_rng(0)
    engine = make_engine(url)
    upgrade(engine)
    count = 0
    with session_scope(make_session_factory(engine)) as s:
        owner = User(name="synthetic")
        areas = [AreaRow(name=f"area-{i}", content_hash="-", plateau_s=p, voxel_size=0.1,
                         stats={}) for i, p in enumerate(PLATEAUS)]
        rows = [PlannerRow(name=f"planner-{i}", version=1) for i in range(planners)]
        s.add_all([owner, *areas, *rows])
        s.flush()
        for skill, planner in enumerate(rows):
            job = Job(user_id=owner.id, planner_id=planner.id, preset="default",
                      runs_per_area=runs, request_hash="-")
            s.add(job)
            s.flush()
            for area in areas:
                for seed in range(runs):
                    cov = float(min(1.0, rng.normal(0.7 + 0.03 * skill, 0.05)))
                    run = Run(job_id=job.id, area_id=area.id, seed=seed, preset="default",
                              seconds=area.plateau_s, status=RunState.SUCCEEDED.value)
                    s.add(run)
                    s.flush()
                    f = float(rng.uniform(0.6, 0.9))
                    s.add(RunResult(
                        run_id=run.id, outcome="succeeded", reason="-",
                        simulated_until_s=area.plateau_s, explored_volume_m3=1000 * cov,
                        volume_at_plateau_m3=1000 * cov, observable_volume_m3=1000.0,
                        coverage=cov, volumetric_efficiency=cov, precision=f, recall=f,
                        fscore=f, rmse_m=0.03, collisions=0, path_length_m=300.0,
                        iterations=200, planning_ms_median=5.0, planning_ms_mean=6.0,
                        planning_ms_max=50.0, wall_seconds=60.0, benchmark_version=VERSION,
                        metrics={"coverage": cov, "explored_observable_m3": 1000 * cov,
                                 "fscore": f, "rmse_m": 0.03, "time_to_90_coverage_s":
                                 None if cov < 0.9 else 400.0}))
                    count += 1
    engine.dispose()
    return count


def _timed(fn: Callable[..., Any], spent: list[float]) -> Callable[..., Any]:
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        began = time.process_time()
        try:
            return fn(*args, **kwargs)
        finally:
            spent.append(time.process_time() - began)

    return wrapper


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    import server.leaderboard as board_module
    from server.db import make_engine, make_session_factory

    with tempfile.TemporaryDirectory(prefix="flybo-intervals-") as tmp:
        url = f"sqlite:///{Path(tmp) / 'flybo.sqlite'}"
        runs = fill(url)
        engine = make_engine(url)
        factory = make_session_factory(engine)
        spent: list[float] = []
        board_module.describe = _timed(board_module.describe, spent)  # type: ignore[assignment]
        board_module.annotate = _timed(board_module.annotate, spent)  # type: ignore[assignment]
        totals, parts = [], []
        for _ in range(args.repeats):
            spent.clear()
            with factory() as session:
                began = time.process_time()
                board = board_module.compute_leaderboard(session, "default",
                                                         benchmark_version=VERSION)
                totals.append(time.process_time() - began)
            parts.append(sum(spent))
        engine.dispose()
    total, part = statistics.median(totals), statistics.median(parts)
    print_table(f"compute_leaderboard, {runs} runs ({len(board.entries)} cells), median of "
                f"{args.repeats}", ["part", "ms", "share"],
                [["whole board", f"{1000 * total:.0f}", "100 %"],
                 ["intervals and tie groups", f"{1000 * part:.0f}", f"{100 * part / total:.0f} %"]])
    write_json("leaderboard_intervals", {"runs": runs, "cells": len(board.entries),
                                         "repeats": args.repeats, "board_s": total,
                                         "statistics_s": part, "share": part / total})


if __name__ == "__main__":
    main()
