"""Baseline datasets on real databases (SQLite, and PostgreSQL when it answers): export, the
file, import as reference results, and bad input that must change nothing.

The source is a SQLite file of hand-made results (`tests.web.stored`); the target is each kind
of database. Imports go through `flybo.baselines_commands.load_file` and the CLI, the paths the
service and users take.
"""

from __future__ import annotations

import json
import lzma
import re
from collections.abc import Iterator
from pathlib import Path

import pytest
from sqlalchemy import func, select
from sqlalchemy.orm import Session, sessionmaker

from flybo.baselines_load import load_file, load_shipped_baselines
from flybo.cli import main
from server.baseline_format import (
    FORMAT_VERSION,
    Dataset,
    DatasetError,
    decode,
    encode,
    read_dataset,
    write_dataset,
)
from server.baselines import REFERENCE_USER, export_dataset
from server.db import make_engine, make_session_factory, session_scope
from server.jobs import job_out, read_job
from server.leaderboard import compute_leaderboard
from server.migrate import upgrade
from server.models import AreaRow, Base, Job, MetricSeries, Run, User
from server.security import create_token
from tests.web.stored import add_area, add_job, add_planner, add_run, current_version

VERSION = current_version()


@pytest.fixture
def source(tmp_path: Path) -> Iterator[sessionmaker[Session]]:
    """alpha (built in): 3 runs on MAZE and 2 on HALL; beta (built in): 2 runs on MAZE, one
    of the exact preset; an uploaded planner's run, a failed run and a legacy run, which a
    dataset leaves out."""
    engine = make_engine(f"sqlite:///{tmp_path / 'source.sqlite'}")
    upgrade(engine)
    factory = make_session_factory(engine)
    with session_scope(factory) as s:
        create_token(s, "alice", "secret")
        alice = s.scalars(select(User).where(User.name == "alice")).one()
        maze, hall = add_area(s, "maze", "MAZE"), add_area(s, "hall", "HALL")
        alpha = add_planner(s, "alpha", method="original")
        beta = add_planner(s, "beta", method="variant")
        mine = add_planner(s, "mine", builtin=False, owner=alice)
        job = add_job(s, alice, alpha)
        for seed, cov in enumerate((0.8, 0.6, 0.7)):
            add_run(s, job, maze, seed, coverage=cov, fscore=0.5 + seed / 10,
                    volume=[0, 1, 2 + seed], recall=[0.1, 0.3])
        for seed, cov in enumerate((0.9, 0.95)):
            add_run(s, job, hall, seed, coverage=cov, fscore=None, volume=[0, 3, 4],
                    recall=[0.2])
        beta_job = add_job(s, alice, beta)
        add_run(s, beta_job, maze, 0, coverage=0.5, fscore=0.4, volume=[0, 2, 2], recall=[0.1])
        add_run(s, beta_job, maze, 1, coverage=0.4, fscore=0.3, volume=[0, 1, 1], recall=[0.1])
        add_run(s, add_job(s, alice, beta, "exact"), maze, 0, coverage=0.45, fscore=0.35,
                volume=[0, 1, 2], recall=[0.1])
        add_run(s, add_job(s, alice, mine), maze, 0, coverage=0.99, fscore=0.9,
                volume=[0, 9, 9], recall=[0.9])
        add_run(s, job, maze, 7, coverage=0.01, fscore=0.01, volume=[0, 0, 0], recall=[0.0],
                status="failed")
        add_run(s, job, maze, 8, coverage=0.02, fscore=0.02, volume=[0, 0, 0], recall=[0.0],
                benchmark_version="legacy")
    yield factory
    engine.dispose()


@pytest.fixture
def dataset_file(source: sessionmaker[Session], tmp_path: Path) -> Path:
    with source() as s:
        dataset = export_dataset(s, VERSION)
    path = tmp_path / "baselines.json.xz"
    write_dataset(dataset, path)
    return path


def _counts(factory: sessionmaker[Session]) -> dict[str, int]:
    with factory() as s:
        return {t.name: int(s.scalar(select(func.count()).select_from(t)) or 0)
                for t in Base.metadata.sorted_tables}


def _board(factory: sessionmaker[Session], preset: str = "default") -> dict[str, object]:
    with factory() as s:
        board = compute_leaderboard(s, preset, benchmark_version=VERSION).model_dump()
    return {k: v for k, v in board.items() if k != "entries"} | {
        "entries": sorted(board["entries"], key=lambda e: (e["planner"], e["area"]))}


def test_export_holds_the_succeeded_runs_of_built_in_planners(dataset_file: Path) -> None:
    dataset = read_dataset(dataset_file, benchmark_version=VERSION)
    assert dataset.format_version == FORMAT_VERSION and dataset.benchmark_version == VERSION
    cells = sorted((r.planner, r.area, r.preset, r.seed) for r in dataset.runs)
    assert cells == sorted([("alpha-v1", "maze", "default", s) for s in range(3)]
                           + [("alpha-v1", "hall", "default", s) for s in range(2)]
                           + [("beta-v1", "maze", "default", s) for s in range(2)]
                           + [("beta-v1", "maze", "exact", 0)])
    assert {p.key for p in dataset.planners} == {"alpha-v1", "beta-v1"}
    assert dataset.suite.runs == 8 and dataset.suite.simulated_s == 16.0
    # The file is xz: compressed JSON, nothing else.
    assert json.loads(lzma.decompress(dataset_file.read_bytes()))["format"] == "flybo-baselines"


def test_import_gives_the_same_leaderboard_as_reference_results(
        source: sessionmaker[Session], sessions: sessionmaker[Session],
        dataset_file: Path) -> None:
    done = load_file(sessions, dataset_file, VERSION)
    assert done is not None and (done.imported, done.skipped) == (8, 0)
    # The uploaded planner is not in the dataset: its run in the default preset changes the
    # source's ranks and relative coverage, not the built-in planners' coverage.
    with source() as s:
        mine = [e for e in compute_leaderboard(s, "default", benchmark_version=VERSION).entries
                if e.planner != "mine-v1"]
    with sessions() as s:
        theirs = compute_leaderboard(s, "default", benchmark_version=VERSION).entries
    assert {(e.planner, e.area): e.coverage for e in theirs} == {
        (e.planner, e.area): e.coverage for e in mine}
    # What each planner is to its paper travels with it, and the board shows it.
    assert {e.planner: e.method for e in theirs} == {"alpha-v1": "original", "beta-v1": "variant"}
    assert _board(sessions, "exact") == _board(source, "exact")
    with sessions() as s:
        jobs = s.scalars(select(Job)).all()
        assert jobs and all(j.reference and j.user.name == REFERENCE_USER for j in jobs)
        assert all(job_out(j).reference for j in jobs)
        polled = read_job(s.connection(), jobs[0].id)  # what GET /api/v1/jobs/{id} answers
        assert polled is not None and polled.reference
        series = s.scalars(select(MetricSeries)).all()
    with source() as s:
        stored = {bytes(m.explored_volume_m3) for m in s.scalars(select(MetricSeries))}
    assert {bytes(m.explored_volume_m3) for m in series} <= stored
    # Exported again, the runs are the same, bit for bit.
    with sessions() as s:
        again = export_dataset(s, VERSION)
    first = read_dataset(dataset_file)
    assert [r.model_dump() for r in again.runs] == [r.model_dump() for r in first.runs]
    assert again.suite == first.suite


def test_importing_twice_adds_nothing(sessions: sessionmaker[Session],
                                      dataset_file: Path) -> None:
    load_file(sessions, dataset_file, VERSION)
    before = _counts(sessions)
    done = load_file(sessions, dataset_file, VERSION)
    assert done is not None and (done.imported, done.skipped) == (0, 8)
    assert _counts(sessions) == before


def _rewrite(path: Path, target: Path, change: dict[str, object]) -> Path:
    raw = json.loads(lzma.decompress(path.read_bytes()))
    raw.update(change)
    target.write_bytes(lzma.compress(json.dumps(raw).encode()))
    return target


def test_other_versions_are_refused_naming_both(sessions: sessionmaker[Session],
                                                dataset_file: Path, tmp_path: Path) -> None:
    before = _counts(sessions)
    newer = _rewrite(dataset_file, tmp_path / "v3.json.xz", {"format_version": 3})
    with pytest.raises(DatasetError,
                       match=r"format version 3; this flybo reads format versions 1, 2 only"):
        load_file(sessions, newer, VERSION)
    with pytest.raises(DatasetError, match=re.escape(f"benchmark version '{VERSION}'; this "
                                                     "service is benchmark version '1999.01-1'")):
        load_file(sessions, dataset_file, "1999.01-1")
    assert _counts(sessions) == before


def test_a_format_1_dataset_loads_with_the_method_unstated(
        sessions: sessionmaker[Session], dataset_file: Path, tmp_path: Path) -> None:
    raw = json.loads(lzma.decompress(dataset_file.read_bytes()))
    for planner in raw["planners"]:
        del planner["method"]
    older = _rewrite(dataset_file, tmp_path / "v1.json.xz",
                     {"format_version": 1, "planners": raw["planners"]})
    done = load_file(sessions, older, VERSION)
    assert done is not None and done.imported == 8
    with sessions() as s:
        entries = compute_leaderboard(s, "default", benchmark_version=VERSION).entries
    assert {e.method for e in entries} == {""}


def _bad_files(good: bytes, tmp: Path) -> dict[str, Path]:
    raw = json.loads(lzma.decompress(good))
    broken_run = json.loads(json.dumps(raw))
    broken_run["runs"][-1]["result"]["coverage"] = "lots"
    wrong_version_run = json.loads(json.dumps(raw))
    wrong_version_run["runs"][-1]["result"]["benchmark_version"] = "other"
    middle = len(good) // 2
    files = {
        "truncated": good[: len(good) - 40],
        "flipped": good[:middle] + bytes([good[middle] ^ 0xFF]) + good[middle + 1:],
        "not xz": b"{\"format\": \"flybo-baselines\"}",
        "not json": lzma.compress(b"{\"format\": "),
        "bad last run": lzma.compress(json.dumps(broken_run).encode()),
        "run of another version": lzma.compress(json.dumps(wrong_version_run).encode()),
        "empty": b"",
    }
    out = {}
    for name, data in files.items():
        path = tmp / f"{name.replace(' ', '-')}.json.xz"
        path.write_bytes(data)
        out[name] = path
    return out


def test_partial_or_corrupt_files_change_nothing(sessions: sessionmaker[Session],
                                                 dataset_file: Path, tmp_path: Path) -> None:
    before = _counts(sessions)
    for name, path in _bad_files(dataset_file.read_bytes(), tmp_path).items():
        with pytest.raises(DatasetError) as caught:
            load_file(sessions, path, VERSION)
        assert str(caught.value), name
        assert _counts(sessions) == before, name


def test_a_conflict_found_while_writing_rolls_everything_back(
        sessions: sessionmaker[Session], dataset_file: Path) -> None:
    """HALL is stored here with other content: found after the planners and MAZE were written
    in the transaction, which then stores none of it."""
    with session_scope(sessions) as s:
        s.add(AreaRow(name="hall", builtin=True, content_hash="f" * 64, plateau_s=700.0,
                      voxel_size=0.1, stats={}))
    before = _counts(sessions)
    with pytest.raises(DatasetError, match="area hall is stored here with other content"):
        load_file(sessions, dataset_file, VERSION)
    assert _counts(sessions) == before


def test_the_cli_refuses_bad_files_and_imports_good_ones(
        sessions: sessionmaker[Session], dataset_file: Path, tmp_path: Path,
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
        database_url: str) -> None:
    monkeypatch.setenv("FLYBO_DATABASE_URL", database_url)
    monkeypatch.setenv("FLYBO_DATA_DIR", str(tmp_path / "data"))
    before = _counts(sessions)
    truncated = tmp_path / "partial.json.xz"
    truncated.write_bytes(dataset_file.read_bytes()[:-100])
    with pytest.raises(SystemExit) as code:
        main(["baselines", "import", str(truncated)])
    assert code.value.code == 2
    assert "nothing was imported" in capsys.readouterr().err
    assert _counts(sessions) == before
    main(["baselines", "import", str(dataset_file)])
    assert "8 reference run(s)" in capsys.readouterr().out
    out = tmp_path / "again.json.xz"
    main(["baselines", "export", "--out", str(out), "--preset", "exact"])
    assert [r.preset for r in read_dataset(out).runs] == ["exact"]
    with pytest.raises(SystemExit):
        main(["baselines", "export", "--out", str(tmp_path / "x.zip")])
    assert "must end in .json.xz" in capsys.readouterr().err


def test_first_start_loads_the_shipped_dataset_into_an_empty_database_only(
        sessions: sessionmaker[Session], dataset_file: Path) -> None:
    load_shipped_baselines(sessions, dataset_file.with_name("missing.json.xz"))  # none: fine
    assert _counts(sessions)["runs"] == 0
    load_shipped_baselines(sessions, dataset_file)
    assert _counts(sessions)["runs"] == 8
    with session_scope(sessions) as s:  # a service that has run something of its own
        s.execute(Run.__table__.delete())
    load_shipped_baselines(sessions, dataset_file)  # jobs are there: not its first start
    assert _counts(sessions)["runs"] == 0


def test_encode_decode_round_trip_and_limits(dataset_file: Path) -> None:
    dataset = read_dataset(dataset_file)
    assert decode(encode(dataset)) == dataset
    assert isinstance(Dataset.model_validate(dataset.model_dump()), Dataset)
