"""`flybo baselines verify`: re-fly sampled cells of a baseline dataset and check they agree.

A cell is a planner on an area in a preset. For each sampled cell one of its runs (its seed
picked with the cells) is flown again exactly as a service flies it: a run row in a scratch
SQLite database, executed by the worker's own `execute_run`. Then:

- `exact` preset (no planning time charged: bit-for-bit repeatable): every number of the result
  but the wall-clock ones (`wall_seconds`, planning times in ms) and every series must be
  identical.
- any other preset (planning time charged as CPU time, which no two flights share exactly):
  coverage, explored volume, F-score and RMSE must each be within the cell's measured spread of
  the stored run of the same seed: |re-flown - stored| <= max(max - min over the cell's runs,
  `FLOOR` x |the cell's mean|). The floor stands in for the spread of a cell whose runs agree to
  the last digit (one run, or every run at full coverage).
"""

from __future__ import annotations

import random
import tempfile
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from flybo.errors import CliError
from server.baseline_format import DatasetError, ResultEntry, RunEntry, SeriesEntry, read_dataset

EXACT_PRESET = "exact"
FLOOR = 0.01
SPREAD_METRICS = ("coverage", "explored_volume_m3", "fscore", "rmse_m")
# Wall-clock numbers: they differ between any two flights, also of the exact preset.
WALL_CLOCK = frozenset({"wall_seconds", "planning_ms_median", "planning_ms_mean",
                        "planning_ms_max", "record"})


@dataclass(frozen=True)
class Check:
    what: str
    stored: Any
    flown: Any
    tolerance: float | None  # None: must be identical
    ok: bool


def compare_exact(stored: RunEntry, result: ResultEntry,
                  series: SeriesEntry | None) -> list[Check]:
    checks = []
    for key in ResultEntry.model_fields:
        if key in WALL_CLOCK:
            continue
        a, b = getattr(stored.result, key), getattr(result, key)
        checks.append(Check(key, a, b, None, a == b))
    a_series = stored.series.blobs() if stored.series else {}
    b_series = series.blobs() if series else {}
    for key in sorted(set(a_series) | set(b_series)):
        a_blob, b_blob = a_series.get(key), b_series.get(key)
        checks.append(Check(f"series {key}", len(a_blob or b""), len(b_blob or b""), None,
                            a_blob == b_blob))
    return checks


def compare_spread(cell: Sequence[RunEntry], stored: RunEntry,
                   result: ResultEntry) -> list[Check]:
    checks = []
    for key in SPREAD_METRICS:
        values = [getattr(r.result, key) for r in cell if getattr(r.result, key) is not None]
        a, b = getattr(stored.result, key), getattr(result, key)
        if a is None or b is None or not values:
            checks.append(Check(key, a, b, None, a is None and b is None))
            continue
        mean = sum(values) / len(values)
        tolerance = max(max(values) - min(values), FLOOR * abs(mean))
        checks.append(Check(key, a, b, tolerance, abs(b - a) <= tolerance))
    return checks


def sample_cells(runs: Sequence[RunEntry], n: int, seed: int,
                 presets: Sequence[str] | None = None) -> list[tuple[list[RunEntry], RunEntry]]:
    """`n` cells (all when fewer) and one run of each, chosen by `seed`."""
    cells: dict[tuple[str, str, str], list[RunEntry]] = defaultdict(list)
    for run in runs:
        if not presets or run.preset in presets:
            cells[run.cell].append(run)
    rng = random.Random(seed)
    keys = sorted(cells)
    chosen = rng.sample(keys, min(n, len(keys)))
    return [(cells[k], rng.choice(sorted(cells[k], key=lambda r: r.seed))) for k in chosen]


def refly(run: RunEntry, folder: Path) -> tuple[ResultEntry, SeriesEntry | None]:
    """Fly `run`'s planner, area, seed, preset and length again through the worker's
    `execute_run`, in a scratch database under `folder`."""
    import base64

    from sqlalchemy import select

    from flybo.local_commands import _reproducibility_record
    from server.catalog import CatalogError, ensure_area, find_planner, sync_builtin_planners
    from server.db import make_engine, make_session_factory, session_scope
    from server.migrate import upgrade
    from server.models import Job, MetricSeries, Run, RunResult, User
    from server.settings import Settings
    from worker.runner import execute_run, install_record_builder

    settings = Settings(data_dir=folder / "data",
                        database_url=f"sqlite:///{folder / 'verify.sqlite'}")
    engine = make_engine(settings.db_url)
    upgrade(engine)
    factory = make_session_factory(engine)
    try:
        with session_scope(factory) as session:
            sync_builtin_planners(session)
            try:
                planner, area = find_planner(session, run.planner), ensure_area(session, run.area)
            except CatalogError as exc:
                raise CliError(f"cannot re-fly {run.planner} on {run.area}: {exc}") from None
            user = User(name="verify")
            session.add(user)
            session.flush()
            job = Job(user_id=user.id, planner_id=planner.id, preset=run.preset,
                      seconds=run.seconds, runs_per_area=1, request_hash="0" * 64)
            session.add(job)
            session.flush()
            row = Run(job_id=job.id, area_id=area.id, seed=run.seed, preset=run.preset,
                      seconds=run.seconds)
            session.add(row)
            session.flush()
            run_id = row.id
        install_record_builder(_reproducibility_record)
        outcome = execute_run(run_id, settings)
        if outcome != "succeeded":
            raise CliError(f"re-flying {run.planner} on {run.area}, seed {run.seed}: {outcome}")
        with factory() as session:
            result = session.scalars(select(RunResult).where(RunResult.run_id == run_id)).one()
            series = session.get(MetricSeries, run_id)
            fields = {k: getattr(result, k) for k in ResultEntry.model_fields}
            flown = ResultEntry(**fields), None if series is None else SeriesEntry(**{
                k: base64.b64encode(getattr(series, k)).decode("ascii")
                for k in SeriesEntry.model_fields})
    finally:
        engine.dispose()
    return flown


def verify(path: Path, sample: int, seed: int, presets: Sequence[str] | None,
           version: str) -> None:
    """Re-fly `sample` cells of the dataset at `path`, which must be of benchmark version
    `version` (this code's); raises `CliError` unless every cell agrees."""
    if sample < 1:
        raise CliError("--sample must be at least 1")
    try:
        dataset = read_dataset(path, benchmark_version=version)
    except DatasetError as exc:
        raise CliError(f"{path}: {exc}") from None
    cells = sample_cells(dataset.runs, sample, seed, presets)
    if not cells:
        raise CliError(f"{path}: no runs{' in ' + ', '.join(presets) if presets else ''}")
    failed = 0
    for cell, run in cells:
        with tempfile.TemporaryDirectory(prefix="flybo-verify-") as tmp:
            result, series = refly(run, Path(tmp))
        checks = (compare_exact(run, result, series) if run.preset == EXACT_PRESET
                  else compare_spread(cell, run, result))
        bad = [c for c in checks if not c.ok]
        failed += bool(bad)
        label = f"{run.planner} on {run.area}, {run.preset}, seed {run.seed}"
        print(f"{'agrees' if not bad else 'DIFFERS'}  {label} ({len(cell)} runs in the cell)")
        for c in bad or [c for c in checks if c.tolerance is not None]:
            within = "identical" if c.tolerance is None else f"tolerance {c.tolerance:.6g}"
            print(f"    {c.what}: stored {c.stored}, re-flown {c.flown} ({within})")
    print(f"{len(cells) - failed} of {len(cells)} cell(s) agree with {path.name} (benchmark "
          f"version {dataset.benchmark_version})")
    if failed:
        raise CliError(f"{failed} cell(s) of {path} did not agree when flown again")
