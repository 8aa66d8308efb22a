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
    "table1",
    "table2",
    "table3",
    "table4",
    "tables",
    "write_csv",
    "write_report",
]


def write_report(data: ReportData, out: Path) -> list[Path]:
    """Write `table1..4.csv`, `report.md` and `figure4..6.{png,svg}` into `out` (created if
    missing); returns the paths written."""
    out.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    parts = [f"# FLYBO report, preset `{data.preset}`, benchmark version "
             f"`{data.benchmark_version}`", ""]
    source = f"From {data.source}: the" if data.source else "The"
    parts += [f"{source} results of benchmark version `{data.benchmark_version}` only. Every "
              "cell is the mean over the succeeded runs, with the smallest and largest run in "
              "brackets.", ""]
    for table in tables(data):
        path = out / f"{table.name}.csv"
        write_csv(table, path)
        written.append(path)
        parts += [f"## {table.title}", "", markdown_table(table), "",
                  f"CSV: [{path.name}]({path.name})", ""]
    for stem, (title, draw) in FIGURES.items():
        written += save_figure(draw(data), out, stem)
        parts += [f"## {title}", "", f"![{title}]({stem}.png)", "",
                  f"SVG: [{stem}.svg]({stem}.svg)", ""]
    md = out / "report.md"
    md.write_text("\n".join(parts), encoding="utf-8")
    written.append(md)
    return written
