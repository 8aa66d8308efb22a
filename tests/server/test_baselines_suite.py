"""A small real suite through the whole baseline machinery: flown by the worker's own
`execute_run` (2 planners x 2 areas x 3 runs of 10 simulated seconds, in the exact and the
default preset), exported by `flybo baselines export`, imported into SQLite and PostgreSQL,
ranked with intervals, reported by `flybo report --dataset` alone, and verified by
`flybo baselines verify`."""

from __future__ import annotations

import csv
import json
import lzma
from collections.abc import Iterator
from pathlib import Path

import pytest
from sqlalchemy import select

from flybo.baselines_load import load_file
from flybo.cli import main
from server.baseline_format import read_dataset
from server.catalog import sync_builtin_planners
from server.db import make_engine, make_session_factory, session_scope
from server.jobs import create_job
from server.leaderboard import compute_leaderboard
from server.migrate import upgrade
from server.models import User
from server.schemas import JobCreate
from server.settings import Settings
from tests.web.stored import current_version
from worker.runner import execute_run

pytestmark = pytest.mark.slow

PLANNERS = ("classic", "rapid")
AREAS = ["maze", "facility-a"]
RUNS, SECONDS = 3, 10.0
PRESETS = ("exact", "default")


# Session scope: a module fixture is set up again whenever the worker runs another file's tests
# in between, and the suite is a minute of flights.
@pytest.fixture(scope="session")
def suite(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Settings, Path]]:
    """The suite flown into a service's SQLite database, and its dataset exported by the
    CLI: (the service's settings, the dataset file)."""
    folder = tmp_path_factory.mktemp("suite")
    settings = Settings(data_dir=folder / "data",
                        database_url=f"sqlite:///{folder / 'flybo.sqlite'}")
    engine = make_engine(settings.db_url)
    upgrade(engine)
    factory = make_session_factory(engine)
    run_ids: list[int] = []
    with session_scope(factory) as s:
        sync_builtin_planners(s)
        user = User(name="alice")
        s.add(user)
        s.flush()
        for planner in PLANNERS:
            for preset in PRESETS:
                created = create_job(s, settings, user, JobCreate(
                    planner=planner, areas=AREAS, runs=RUNS, seconds=SECONDS, preset=preset))
                run_ids += [run_id for run_id, _ in created.runs]
    for run_id in run_ids:
        assert execute_run(run_id, settings) == "succeeded"
    engine.dispose()
    dataset = folder / "suite.json.xz"
    with pytest.MonkeyPatch.context() as env:
        env.setenv("FLYBO_DATABASE_URL", settings.db_url)
        env.setenv("FLYBO_DATA_DIR", str(settings.data_dir))
        main(["baselines", "export", "--out", str(dataset)])
    yield settings, dataset


def test_the_dataset_holds_the_whole_suite(suite: tuple[Settings, Path]) -> None:
    _, path = suite
    dataset = read_dataset(path, benchmark_version=current_version())
    assert dataset.suite.runs == len(PLANNERS) * len(AREAS) * RUNS * len(PRESETS)
    # Each run ends on the first physics step at or past its length.
    assert dataset.suite.simulated_s == pytest.approx(dataset.suite.runs * SECONDS, abs=0.1)
    assert dataset.suite.wall_time_s is not None and dataset.suite.wall_time_s > 0
    assert all(r.series is not None and r.result.record for r in dataset.runs)
    raw = json.loads(lzma.decompress(path.read_bytes()))
    assert not any(k in raw["runs"][0] for k in ("artifacts", "mesh", "recording"))


def test_imported_suite_ranks_with_intervals(suite: tuple[Settings, Path],
                                             database_url: str) -> None:
    settings, path = suite
    engine = make_engine(database_url)
    upgrade(engine)
    target = make_session_factory(engine)
    try:
        done = load_file(target, path, current_version())
        assert done is not None and done.imported == len(read_dataset(path).runs)
        source = make_session_factory(make_engine(settings.db_url))
        for preset in PRESETS:
            with target() as s:
                board = compute_leaderboard(s, preset, benchmark_version=current_version())
            with source() as s:
                flown = compute_leaderboard(s, preset, benchmark_version=current_version())
            assert board == flown  # the service that flew them ranks them the same
            assert len(board.entries) == len(PLANNERS) * len(AREAS)
            for e in board.entries:
                assert e.runs == RUNS
                assert e.coverage.ci_low is not None and e.coverage.ci_high is not None
                # Within rounding: the mean and the bootstrap means are summed in other orders.
                slack = 1e-12
                assert e.coverage.min - slack <= e.coverage.ci_low  # type: ignore[operator]
                assert e.coverage.ci_low <= e.coverage.mean + slack  # type: ignore[operator]
                assert e.coverage.mean - slack <= e.coverage.ci_high  # type: ignore[operator]
                assert e.coverage.ci_high <= e.coverage.max + slack  # type: ignore[operator]
                assert e.coverage_group_rank in (1, 2)
            ranks = sorted(p.rank for p in board.overall)
            assert ranks in ([1, 1], [1, 2])
            for p in board.overall:
                assert p.mean_coverage_rank_ci is not None
                tied = ranks == [1, 1]
                other = next(q for q in board.overall if q is not p)
                assert other.mean_coverage_rank_ci is not None
                apart = (p.mean_coverage_rank_ci.high < other.mean_coverage_rank_ci.low
                         or other.mean_coverage_rank_ci.high < p.mean_coverage_rank_ci.low)
                assert tied != apart
        with target() as s:
            assert s.scalar(select(User.name).where(User.name == "flybo-reference"))
    finally:
        engine.dispose()


def test_the_report_of_the_dataset_alone(suite: tuple[Settings, Path], tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    settings, path = suite
    docs = tmp_path / "docs"
    main(["report", "--dataset", str(path), "--out", str(docs / "results"), "--markdown",
          str(docs / "RESULTS.md"), "--preset", "default"])
    text = (docs / "RESULTS.md").read_text()
    dataset = read_dataset(path)
    assert f"benchmark version `{dataset.benchmark_version}`" in text
    assert f"From the baseline dataset {path.name}" in text
    assert f"**The suite**: {dataset.suite.runs} runs in the dataset (12 of preset `default`" \
        in text and "of wall time from the first run's start" in text
    assert "](results/figure6.png)" in text and "](results/table2.csv)" in text
    for name in ("table1.csv", "table2.csv", "table3.csv", "table4.csv", "figure6.svg"):
        assert (docs / "results" / name).stat().st_size > 0
    # The tables hold the service's numbers: the leaderboard of the database that flew them.
    with make_session_factory(make_engine(settings.db_url))() as s:
        board = compute_leaderboard(s, "default", benchmark_version=current_version())
    with (docs / "results" / "table2.csv").open() as f:
        rows = {r["planner"]: r for r in csv.DictReader(f)}
    for p in board.overall:
        assert int(rows[p.planner]["rank"]) == p.rank
        assert p.mean_coverage_ci is not None
        assert float(rows[p.planner]["average coverage % ci low"]) == pytest.approx(
            100 * p.mean_coverage_ci.low, abs=1e-4)


def test_verify_agrees_on_exact_cells_and_finds_a_tampered_one(
        suite: tuple[Settings, Path], tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    _, path = suite
    main(["baselines", "verify", str(path), "--sample", "1", "--preset", "exact"])
    out = capsys.readouterr().out
    assert "agrees" in out and "1 of 1 cell(s) agree" in out
    raw = json.loads(lzma.decompress(path.read_bytes()))
    for run in raw["runs"]:
        if run["preset"] == "exact":
            run["result"]["coverage"] += 1e-9  # a stored number that the code does not give
    tampered = tmp_path / "tampered.json.xz"
    tampered.write_bytes(lzma.compress(json.dumps(raw).encode()))
    with pytest.raises(SystemExit) as code:
        main(["baselines", "verify", str(tampered), "--sample", "1", "--preset", "exact",
              "--seed", "3"])
    assert code.value.code == 2
    captured = capsys.readouterr()
    assert "DIFFERS" in captured.out and "coverage: stored" in captured.out
    assert "did not agree when flown again" in captured.err
