"""`flybo report --dataset FILE`: the report of a baseline dataset alone, without a service.

The dataset is loaded into a scratch SQLite database exactly as `flybo baselines import` loads
it, and the leaderboard, curves and areas are computed there by the functions the API serves
them with: a report of a dataset is the report of a service holding only that dataset. The
dataset's benchmark version is reported, whatever this code's version is.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from sqlalchemy import select

from flybo.report_data import CURVE_POINTS, ReportData, ReportError
from server.baseline_format import DatasetError, read_dataset
from server.baselines import fingerprint, import_dataset
from server.db import make_engine, make_session_factory, session_scope
from server.leaderboard import compute_leaderboard
from server.migrate import upgrade
from server.models import AreaRow
from server.routes.areas import area_out
from server.routes.curves import build_curves


def dataset_report_data(path: Path, preset: str = "default") -> ReportData:
    """Everything the report needs, from the dataset at `path` (its `preset` runs)."""
    try:
        data = path.read_bytes()
        dataset = read_dataset(path)
    except (OSError, DatasetError) as exc:
        raise ReportError(f"{path}: {exc}") from None
    version = dataset.benchmark_version
    with tempfile.TemporaryDirectory(prefix="flybo-report-") as tmp:
        engine = make_engine(f"sqlite:///{Path(tmp) / 'report.sqlite'}")
        try:
            upgrade(engine)
            factory = make_session_factory(engine)
            with session_scope(factory) as session:
                import_dataset(session, dataset, fingerprint(data))
            with factory() as session:
                board = compute_leaderboard(session, preset, benchmark_version=version)
                areas = [area_out(r) for r in
                         session.scalars(select(AreaRow).order_by(AreaRow.name))]
                curves = {area: build_curves(session, preset, area, CURVE_POINTS,
                                             benchmark_version=version)
                          for area in board.areas}
        finally:
            engine.dispose()
    runs = [r for r in dataset.runs if r.preset == preset]
    return ReportData(preset=preset, board=board, areas=areas, curves=curves,
                      source=f"the baseline dataset {path.name}", suite=dataset.suite,
                      suite_runs=len(runs))
