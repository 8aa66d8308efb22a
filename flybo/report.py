"""`flybo report`: the paper's Tables 1-4 (CSV and Markdown) and Figures 4-6 (PNG and SVG)
from a service's API.

Two parts: `fetch_report_data` (`flybo.report_data`) reads the API (`/areas`, `/leaderboard`,
`/curves`) through any `httpx.Client`, a test's `TestClient` included; `write_report` turns that
data into files and touches no network. Tables show what the website shows: per planner and area
the mean over the succeeded runs with the smallest and largest run; coverage and F-score in %,
RMSE in cm. A report is of one benchmark version, named in its title (results of different
versions are never ranked together). The tables are made in `flybo.report_tables`, the figures
in `flybo.report_figures`.
"""

from __future__ import annotations

import os
from pathlib import Path

from flybo.report_data import CURVE_POINTS, ReportData, ReportError, fetch_report_data
from flybo.report_figures import FIGURES, PALETTE, curves_figure, pareto_figure, save_figure
from flybo.report_tables import (
    DASH,
    Cell,
    Table,
    markdown_table,
    table1,
    table2,
    table3,
    table4,
    tables,
    write_csv,
)

__all__ = [
    "CURVE_POINTS",
    "DASH",
    "FIGURES",
    "PALETTE",
    "Cell",
    "ReportData",
    "ReportError",
    "Table",
    "curves_figure",
    "fetch_report_data",
    "markdown_table",
    "pareto_figure",
    "suite_lines",
    "table1",
    "table2",
    "table3",
    "table4",
    "tables",
    "write_csv",
    "write_report",
]


def write_report(data: ReportData, out: Path, markdown: Path | None = None) -> list[Path]:
    """Write `table1..4.csv`, the Markdown (`markdown`, default `out/report.md`, its links
    relative to it) and `figure4..6.{png,svg}` into `out` (created if missing); returns the
    paths written."""
    out.mkdir(parents=True, exist_ok=True)
    md = markdown or out / "report.md"
    md.parent.mkdir(parents=True, exist_ok=True)
    prefix = Path(os.path.relpath(out.resolve(), md.parent.resolve()))

    def link(name: str) -> str:
        return (prefix / name).as_posix()

    written: list[Path] = []
    parts = [f"# FLYBO report, preset `{data.preset}`, benchmark version "
             f"`{data.benchmark_version}`", ""]
    source = f"From {data.source}: the" if data.source else "The"
    parts += [f"{source} results of benchmark version `{data.benchmark_version}` only. Every "
              "cell is the mean over the succeeded runs with its 95 % confidence interval in "
              "square brackets (percentile bootstrap, "
              f"{data.board.statistics.resamples if data.board.statistics else 0} resamples), "
              "and, where shown, the smallest and largest run in round brackets. Planners "
              "whose intervals overlap share a rank (`docs/statistics.md`).", ""]
    parts += suite_lines(data)
    for table in tables(data):
        path = out / f"{table.name}.csv"
        write_csv(table, path)
        written.append(path)
        parts += [f"## {table.title}", "", markdown_table(table), "",
                  f"CSV: [{path.name}]({link(path.name)})", ""]
    for stem, (title, draw) in FIGURES.items():
        written += save_figure(draw(data), out, stem)
        parts += [f"## {title}", "", f"![{title}]({link(stem + '.png')})", "",
                  f"SVG: [{stem}.svg]({link(stem + '.svg')})", ""]
    md.write_text("\n".join(parts), encoding="utf-8")
    written.append(md)
    return written


def _duration(seconds: float) -> str:
    hours, rest = divmod(round(seconds), 3600)
    return f"{hours} h {rest // 60:02d} min" if hours else f"{rest // 60} min {rest % 60:02d} s"


def suite_lines(data: ReportData) -> list[str]:
    """What a dataset's suite took: runs, simulated time, wall time."""
    suite = data.suite
    if suite is None:
        return []
    board = data.board
    wall = (f"{_duration(suite.wall_time_s)} of wall time from the first run's start to the "
            "last run's end" if suite.wall_time_s is not None else "no recorded wall time")
    return [f"**The suite**: {suite.runs} runs in the dataset ({data.suite_runs} of preset "
            f"`{data.preset}`: {len(board.overall)} planners on {len(board.areas)} areas), "
            f"{suite.simulated_s:,.0f} simulated seconds, {wall} (the runs' own wall times "
            f"add up to {_duration(suite.run_wall_time_s)}).", ""]
