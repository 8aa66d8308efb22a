"""`flybo report` from a real app on a SQLite file holding known results: the files exist, the
CSVs hold the seeded numbers, the figures are valid PNG and SVG, and a report is of one
benchmark version."""

from __future__ import annotations

import csv
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from flybo.app import create_app
from flybo.report import ReportError, fetch_report_data, write_report
from server.db import make_engine, make_session_factory, session_scope
from server.migrate import upgrade
from server.models import User
from server.security import create_token
from server.settings import Settings
from tests.web.stored import add_area, add_job, add_planner, add_run, current_version

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


@pytest.fixture
def client(tmp_path: Path) -> Iterator[TestClient]:
    """alpha: 2 runs on MAZE (coverage 0.8 and 0.6, F-score 0.5 and 0.7, paths 10 and 11 m);
    beta: 1 run (coverage 0.9, F 0.4); gamma: 1 run (0.5, F 0.3); one failed run of alpha
    that counts nowhere; an area without results; and a legacy run of gamma (coverage 0.95),
    which only the legacy report counts."""
    settings = Settings(data_dir=tmp_path / "data",
                        database_url=f"sqlite:///{tmp_path / 'flybo.sqlite'}")
    engine = make_engine(settings.db_url)
    upgrade(engine)
    with session_scope(make_session_factory(engine)) as s:
        create_token(s, "alice", settings.secret_key)
        alice = s.query(User).filter_by(name="alice").one()
        maze = add_area(s, "maze", "MAZE")
        add_area(s, "empty-hall", "EMPTY HALL")
        alpha, beta, gamma = (add_planner(s, n) for n in ("alpha", "beta", "gamma"))
        job = add_job(s, alice, alpha)
        add_run(s, job, maze, 0, coverage=0.8, fscore=0.5, volume=[0, 1, 2, 3, 4],
                recall=[0.1, 0.3])
        add_run(s, job, maze, 1, coverage=0.6, fscore=0.7, volume=[0, 2, 4], recall=[0.2])
        add_run(s, job, maze, 2, coverage=0.99, fscore=0.99, volume=[9, 9, 9], recall=[0.9],
                status="failed")
        add_run(s, add_job(s, alice, beta), maze, 0, coverage=0.9, fscore=0.4,
                volume=[0, 5, 6], recall=[0.2])
        add_run(s, add_job(s, alice, gamma), maze, 0, coverage=0.5, fscore=0.3,
                volume=[0, 1, 1], recall=[0.1], time_to_90=30.0)
        add_run(s, add_job(s, alice, gamma), maze, 1, coverage=0.95, fscore=0.9,
                volume=[0, 8, 9], recall=[0.9], benchmark_version="legacy")
    engine.dispose()
    with TestClient(create_app(settings, sweeper=False, sync_areas=False,
                               benchmark_version=current_version())) as test_client:
        yield test_client


def _csv(path: Path) -> list[dict[str, str]]:
    with path.open(newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def test_report_from_a_real_app(client: TestClient, tmp_path: Path) -> None:
    out = tmp_path / "report"
    written = write_report(fetch_report_data(client, "default"), out)
    names = {p.name for p in written}
    assert names == {"table1.csv", "table2.csv", "table3.csv", "table4.csv", "report.md",
                     "figure4.png", "figure4.svg", "figure5.png", "figure5.svg",
                     "figure6.png", "figure6.svg"}
    assert all((out / n).stat().st_size > 0 for n in names)

    areas = {r["area"]: r for r in _csv(out / "table1.csv")}
    assert set(areas) == {"maze", "empty-hall"}
    maze = areas["maze"]
    assert (maze["title"], maze["bounding x (m)"], maze["bounding z (m)"], maze["rooms"],
            maze["faces"], maze["indoor"], maze["plateau (s)"]) == (
        "MAZE", "20.0", "2.5", "3", "100", "indoor", "700.0")

    coverage = _csv(out / "table2.csv")
    assert [r["planner"] for r in coverage] == ["beta-v1", "alpha-v1", "gamma-v1"]
    alpha = coverage[1]
    assert alpha["rank"] == "2" and alpha["mean coverage rank"] == "2.0"
    assert float(alpha["maze coverage % mean"]) == pytest.approx(70.0)
    assert float(alpha["maze coverage % min"]) == pytest.approx(60.0)
    assert float(alpha["maze coverage % max"]) == pytest.approx(80.0)
    assert float(alpha["maze coverage % ci low"]) == pytest.approx(60.0)
    assert float(alpha["maze coverage % ci high"]) == pytest.approx(80.0)
    # One area: alpha is second in every resample, so its mean rank's interval is [2, 2].
    assert (alpha["mean coverage rank ci low"], alpha["mean coverage rank ci high"]) == (
        "2.0", "2.0")
    assert float(alpha["average coverage %"]) == pytest.approx(70.0)
    # Relative coverage: volume at the plateau (4 m³ in both of alpha's runs) over the best
    # planner's mean (beta's 6 m³).
    assert float(alpha["relative coverage %"]) == pytest.approx(100 * 4 / 6)

    surface = {r["planner"]: r for r in _csv(out / "table3.csv")}
    assert list(surface) == ["alpha-v1", "beta-v1", "gamma-v1"]  # by F-score rank
    assert float(surface["alpha-v1"]["maze F-score % mean"]) == pytest.approx(60.0)
    assert float(surface["alpha-v1"]["maze F-score % max"]) == pytest.approx(70.0)
    assert float(surface["alpha-v1"]["maze RMSE cm mean"]) == pytest.approx(2.0)

    timing = [r for r in _csv(out / "table4.csv") if r["planner"] == "alpha-v1"]
    assert len(timing) == 1 and timing[0]["area"] == "maze" and timing[0]["runs"] == "2"
    assert float(timing[0]["path length m mean"]) == pytest.approx(10.5)
    assert float(timing[0]["iterations min"]) == 5 and float(timing[0]["iterations max"]) == 6
    assert float(timing[0]["planning time ms mean"]) == pytest.approx(3.0)

    # The leaderboard metrics the paper's columns do not show: time to 90 % coverage.
    gamma = next(r for r in coverage if r["planner"] == "gamma-v1")
    assert float(gamma["average time to 90 % s"]) == 30.0 and alpha["average time to 90 % s"] == ""
    timing_gamma = next(r for r in _csv(out / "table4.csv") if r["planner"] == "gamma-v1")
    assert timing_gamma["runs"] == "1"  # its legacy run is another version's
    assert float(timing_gamma["time to 90 % s mean"]) == 30.0

    markdown = (out / "report.md").read_text()
    assert markdown.startswith(f"# FLYBO report, preset `default`, benchmark version "
                               f"`{current_version()}`")
    # Table 4: the mean, its bootstrap interval (two runs: the resampled means are 60, 70 or
    # 80 %) and the extremes; Table 2 leaves the extremes to its CSV.
    assert "70.0 [60.0, 80.0] (60.0–80.0)" in markdown and "![Figure 4" in markdown
    assert "| 2 | alpha-v1 * | 70.0 [60.0, 80.0] |" in markdown
    assert "beta-v1 *" in markdown  # beta is in the Pareto set

    for stem in ("figure4", "figure5", "figure6"):
        assert (out / f"{stem}.png").read_bytes().startswith(PNG_SIGNATURE)
        root = ET.parse(out / f"{stem}.svg").getroot()
        assert root.tag.endswith("svg")


def test_report_of_another_benchmark_version(client: TestClient, tmp_path: Path) -> None:
    data = fetch_report_data(client, "default", "legacy")
    assert data.benchmark_version == "legacy"
    assert [p.planner for p in data.board.overall] == ["gamma-v1"]
    assert [(p.planner, p.runs) for p in data.curves["maze"].planners] == [("gamma-v1", 1)]
    write_report(data, tmp_path / "legacy")
    coverage = _csv(tmp_path / "legacy" / "table2.csv")
    assert [(r["planner"], float(r["maze coverage % mean"])) for r in coverage] == [
        ("gamma-v1", pytest.approx(95.0))]
    assert "benchmark version `legacy`" in (tmp_path / "legacy" / "report.md").read_text()
    with pytest.raises(ReportError, match=r"unknown benchmark version '1999\.01-1'; known: "):
        fetch_report_data(client, "default", "1999.01-1")


def test_report_without_results(tmp_path: Path) -> None:
    settings = Settings(data_dir=tmp_path / "data",
                        database_url=f"sqlite:///{tmp_path / 'flybo.sqlite'}")
    with TestClient(create_app(settings, sweeper=False, sync_areas=False)) as client:
        written = write_report(fetch_report_data(client, "exact"), tmp_path / "empty")
    assert len(written) == 11
    assert _csv(tmp_path / "empty" / "table2.csv") == []
    assert "no results yet" in (tmp_path / "empty" / "report.md").read_text()
    assert (tmp_path / "empty" / "figure6.png").read_bytes().startswith(PNG_SIGNATURE)


def test_the_areas_page_shows_table1(client: TestClient) -> None:
    page = client.get("/areas").text
    table = page[page.index("id='areas-table'"):page.index("</table>", page.index(
        "id='areas-table'"))]
    assert "Table 1" in table and "<a href='#area-maze'>maze</a>" in table
    assert "20 × 20 × 2.5" in table and "empty-hall" in table
