"""The tables of `flybo report`: the paper's Tables 1-4, as CSV and as Markdown.

Tables show what the website shows: per planner and area the mean over the succeeded runs with
its bootstrap 95 % interval and the smallest and largest run; coverage and F-score in %, RMSE in
cm; and each leaderboard metric of the measures that the paper's columns do not show
(`Leaderboard.metrics`, such as the time to 90 % coverage), in its own unit. Ranks are shared
by tie groups (`docs/statistics.md`). The CSVs hold every number; the Markdown of the wide
Tables 2 and 3 leaves the smallest and largest run to the CSV and Table 4.
"""

from __future__ import annotations

import csv
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from flybo.report_data import ReportData
from server.schemas import AreaOut, Interval, Leaderboard, LeaderboardEntry, MetricOut, Spread

Cell = str | int | float | None
DASH = "–"
# Leaderboard metrics the paper's columns show already; the others get columns of their own.
SHOWN_METRICS = frozenset({"coverage", "fscore", "rmse_m"})


def extra_metrics(board: Leaderboard) -> list[MetricOut]:
    return [m for m in board.metrics if m.key not in SHOWN_METRICS]


def _label(m: MetricOut) -> str:
    return f"{m.label} {m.unit}".strip()


def _digits(m: MetricOut) -> int:
    precision = re.search(r"\.(\d+)", m.fmt)
    return int(precision.group(1)) if precision else 0


@dataclass(frozen=True)
class Table:
    name: str  # file stem
    title: str
    header: list[str]
    rows: list[list[Cell]]
    # The Markdown version: the website's cells ("mean (min–max)"); None: the CSV's own.
    markdown_header: list[str] | None = None
    markdown_rows: list[list[str]] | None = None


def _scaled(value: float | None, scale: float = 1.0) -> float | None:
    return None if value is None else round(value * scale, 6)


def _spread_cells(s: Spread, scale: float = 1.0) -> list[Cell]:
    return [_scaled(s.mean, scale), _scaled(s.min, scale), _scaled(s.max, scale),
            _scaled(s.ci_low, scale), _scaled(s.ci_high, scale)]


def _interval_cells(i: Interval | None, scale: float = 1.0) -> list[Cell]:
    return [None, None] if i is None else [_scaled(i.low, scale), _scaled(i.high, scale)]


def _fmt(value: float | None, digits: int, scale: float = 1.0) -> str:
    return DASH if value is None else f"{value * scale:.{digits}f}"


def _ci_text(mean: float | None, low: float | None, high: float | None, digits: int,
             scale: float = 1.0) -> str:
    """The mean and its 95 % interval: "70.0 [65.1, 75.0]"."""
    if mean is None:
        return DASH
    if low is None or high is None:
        return _fmt(mean, digits, scale)
    return (f"{_fmt(mean, digits, scale)} [{_fmt(low, digits, scale)}, "
            f"{_fmt(high, digits, scale)}]")


def _mean_text(value: float | None, i: Interval | None, digits: int,
               scale: float = 1.0) -> str:
    return _ci_text(value, None if i is None else i.low, None if i is None else i.high, digits,
                    scale)


def _spread_text(s: Spread, digits: int, scale: float = 1.0, *, extremes: bool = True) -> str:
    """"mean [interval] (min–max)", or without the extremes."""
    text = _ci_text(s.mean, s.ci_low, s.ci_high, digits, scale)
    if s.mean is None or not extremes:
        return text
    return f"{text} ({_fmt(s.min, digits, scale)}{DASH}{_fmt(s.max, digits, scale)})"


def _spread_header(label: str) -> list[str]:
    return [f"{label} mean", f"{label} min", f"{label} max", f"{label} ci low",
            f"{label} ci high"]


def _interval_header(label: str) -> list[str]:
    return [label, f"{label} ci low", f"{label} ci high"]


def table1(areas: Sequence[AreaOut]) -> Table:
    """The areas' statistics: one row per area."""
    skip = {"title", "start", "file", "bounding_volume_m", "rooms", "levels", "faces",
            "complexity", "indoor"}
    extra = sorted({k for a in areas for k in a.stats} - skip)
    header = ["area", "title", "bounding x (m)", "bounding y (m)", "bounding z (m)", "rooms",
              "levels", "faces", "complexity", "indoor", "plateau (s)", "voxel (m)", *extra]
    rows: list[list[Cell]] = []
    for a in areas:
        box = list(a.stats.get("bounding_volume_m") or [None, None, None])[:3]
        indoor = a.stats.get("indoor")
        rows.append([a.name, a.title, *box, a.stats.get("rooms"), a.stats.get("levels"),
                     a.stats.get("faces"), a.stats.get("complexity"),
                     None if indoor is None else ("indoor" if indoor else "outdoor"),
                     a.plateau_s, a.voxel_size, *(_plain(a.stats.get(k)) for k in extra)])
    md_rows = [[_md(c) for c in r[:2]] + [" × ".join(_md(c) for c in r[2:5])]
               + [_md(c) for c in r[5:]] for r in rows]
    md_header = [header[0], header[1], "bounding volume (m)", *header[5:]]
    return Table("table1", "Table 1: statistics of the areas", header, rows, md_header, md_rows)


def _plain(value: Any) -> Cell:
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, str | int | float) or value is None:
        return value
    if isinstance(value, list):
        return " × ".join(str(v) for v in value)
    return str(value)


def _entries(board: Leaderboard) -> dict[tuple[str, str], LeaderboardEntry]:
    return {(e.planner, e.area): e for e in board.entries}


def table2(board: Leaderboard) -> Table:
    """Coverage per area in % (mean, min, max over runs), averages and ranks."""
    entries = _entries(board)
    header = ["rank", "planner", "baseline"]
    md_header = ["Rank", "Planner"]
    for area in board.areas:
        header += _spread_header(f"{area} coverage %")
        md_header.append(area)
    header += [*_interval_header("average coverage %"),
               *_interval_header("relative coverage %"), *_interval_header("mean coverage rank"),
               *_interval_header("mean F-score rank"), "pareto"]
    md_header += ["Average", "Relative", "Avg. rank"]
    extra = extra_metrics(board)
    header += [f"average {_label(m)}" for m in extra]
    md_header += [f"Avg. {_label(m)}" for m in extra]
    rows: list[list[Cell]] = []
    md_rows: list[list[str]] = []
    for p in board.overall:
        row: list[Cell] = [p.rank, p.planner, "yes" if p.builtin else "no"]
        md = [str(p.rank), p.planner + (" *" if p.pareto else "")]
        for area in board.areas:
            e = entries.get((p.planner, area))
            row += _spread_cells(e.coverage, 100) if e else [None] * 5
            md.append(_spread_text(e.coverage, 1, 100, extremes=False) if e else DASH)
        row += [_scaled(p.mean_coverage, 100), *_interval_cells(p.mean_coverage_ci, 100),
                _scaled(p.mean_relative_coverage, 100),
                *_interval_cells(p.mean_relative_coverage_ci, 100),
                _scaled(p.mean_coverage_rank), *_interval_cells(p.mean_coverage_rank_ci),
                _scaled(p.mean_fscore_rank), *_interval_cells(p.mean_fscore_rank_ci),
                "yes" if p.pareto else "no"]
        md += [_mean_text(p.mean_coverage, p.mean_coverage_ci, 1, 100),
               _mean_text(p.mean_relative_coverage, p.mean_relative_coverage_ci, 1, 100),
               _mean_text(p.mean_coverage_rank, p.mean_coverage_rank_ci, 1)]
        row += [_scaled(p.mean_metrics.get(m.key)) for m in extra]
        md += [_fmt(p.mean_metrics.get(m.key), _digits(m)) for m in extra]
        rows.append(row)
        md_rows.append(md)
    return Table("table2", "Table 2: coverage per area, % (mean [95 % interval] over runs); "
                 "planners whose mean-rank intervals overlap share a rank; * marks the Pareto "
                 "set", header, rows, md_header, md_rows)


def table3(board: Leaderboard) -> Table:
    """F-score (%) and RMSE (cm) of the final mesh per area, averages and the F-score rank."""
    entries = _entries(board)
    header = ["planner", "baseline"]
    md_header = ["Planner"]
    for area in board.areas:
        header += _spread_header(f"{area} F-score %") + _spread_header(f"{area} RMSE cm")
        md_header += [f"{area} F", f"{area} RMSE"]
    header += [*_interval_header("average F-score %"), "average RMSE cm",
               *_interval_header("mean F-score rank")]
    md_header += ["Avg. F", "Avg. RMSE", "Avg. F rank"]
    rows: list[list[Cell]] = []
    md_rows: list[list[str]] = []
    ordered = sorted(board.overall, key=lambda p: (p.mean_fscore_rank is None,
                                                   p.mean_fscore_rank or 0.0))
    for p in ordered:
        row: list[Cell] = [p.planner, "yes" if p.builtin else "no"]
        md = [p.planner]
        for area in board.areas:
            e = entries.get((p.planner, area))
            if e is None:
                row += [None] * 10
                md += [DASH, DASH]
                continue
            row += _spread_cells(e.fscore, 100) + _spread_cells(e.rmse_m, 100)
            md += [_spread_text(e.fscore, 1, 100, extremes=False),
                   _spread_text(e.rmse_m, 2, 100, extremes=False)]
        row += [_scaled(p.mean_fscore, 100), *_interval_cells(p.mean_fscore_ci, 100),
                _scaled(p.mean_rmse_m, 100), _scaled(p.mean_fscore_rank),
                *_interval_cells(p.mean_fscore_rank_ci)]
        md += [_mean_text(p.mean_fscore, p.mean_fscore_ci, 1, 100), _fmt(p.mean_rmse_m, 2, 100),
               _mean_text(p.mean_fscore_rank, p.mean_fscore_rank_ci, 1)]
        rows.append(row)
        md_rows.append(md)
    return Table("table3", "Table 3: surface reconstruction, F-score % and RMSE cm "
                 "(mean [95 % interval] over runs)", header, rows, md_header, md_rows)


def table4(board: Leaderboard) -> Table:
    """Per area and planner: iterations, planning time per iteration, path length, and the
    area's coverage and F-score with their ranks."""
    header = ["area", "planner", "runs", *_spread_header("iterations"),
              *_spread_header("planning time ms"), *_spread_header("path length m"),
              *_spread_header("coverage %"), *_spread_header("F-score %"), "collisions",
              "coverage rank", "F-score rank", "coverage group rank", "F-score group rank"]
    md_header = ["Area", "Planner", "Runs", "Iterations", "Planning time, ms",
                 "Path length, m", "Coverage, %", "F-score, %", "Collisions", "Coverage rank",
                 "F-score rank", "Coverage group", "F-score group"]
    extra = extra_metrics(board)
    for m in extra:
        header += _spread_header(_label(m))
        md_header.append(_label(m))
    empty = Spread(mean=None, min=None, max=None)
    rows: list[list[Cell]] = []
    md_rows: list[list[str]] = []
    for area in board.areas:
        here = sorted((e for e in board.entries if e.area == area),
                      key=lambda e: (e.coverage_rank, e.planner))
        for e in here:
            rows.append([area, e.planner, e.runs, *_spread_cells(e.iterations),
                         *_spread_cells(e.planning_ms), *_spread_cells(e.path_length_m),
                         *_spread_cells(e.coverage, 100), *_spread_cells(e.fscore, 100),
                         e.collisions, e.coverage_rank, e.fscore_rank, e.coverage_group_rank,
                         e.fscore_group_rank,
                         *(c for m in extra for c in _spread_cells(e.metrics.get(m.key, empty)))])
            md_rows.append([area, e.planner, str(e.runs), _spread_text(e.iterations, 0),
                            _spread_text(e.planning_ms, 1), _spread_text(e.path_length_m, 1),
                            _spread_text(e.coverage, 1, 100), _spread_text(e.fscore, 1, 100),
                            str(e.collisions), _fmt(e.coverage_rank, 1),
                            _fmt(e.fscore_rank, 1), _md(e.coverage_group_rank),
                            _md(e.fscore_group_rank),
                            *(_spread_text(e.metrics.get(m.key, empty), _digits(m))
                              for m in extra)])
    return Table("table4", "Table 4: planning per area: iterations, planning time per "
                 "iteration (median of a run), path length (mean [95 % interval] (min–max) "
                 "over runs); planners whose intervals overlap share a group rank",
                 header, rows, md_header, md_rows)


def tables(data: ReportData) -> list[Table]:
    return [table1(data.areas), table2(data.board), table3(data.board), table4(data.board)]


def _md(value: Cell) -> str:
    if value is None:
        return DASH
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


def _md_escape(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def markdown_table(table: Table) -> str:
    header = table.markdown_header or table.header
    rows = table.markdown_rows or [[_md(c) for c in r] for r in table.rows]
    lines = ["| " + " | ".join(_md_escape(h) for h in header) + " |",
             "| " + " | ".join("---" for _ in header) + " |"]
    lines += ["| " + " | ".join(_md_escape(c) for c in r) + " |" for r in rows]
    if not rows:
        lines.append("| " + " | ".join(["no results yet", *([""] * (len(header) - 1))]) + " |")
    return "\n".join(lines)


def write_csv(table: Table, path: Path) -> None:
    with path.open("w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f)
        writer.writerow(table.header)
        writer.writerows([["" if c is None else c for c in r] for r in table.rows])
