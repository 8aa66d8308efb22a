"""`flybo report`: the paper's Tables 1-4 (CSV and Markdown) and Figures 4-6 (PNG and SVG)
from a service's API.

Two parts: `fetch_report_data` reads the API (`/areas`, `/leaderboard`, `/curves`) through any
`httpx.Client`, a test's `TestClient` included; `write_report` turns that data into files and
touches no network. Tables show what the website shows: per planner and area the mean over the
succeeded runs with the smallest and largest run; coverage and F-score in %, RMSE in cm.
"""

from __future__ import annotations

import csv
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import httpx

from server.schemas import (
    AreaOut,
    Band,
    Curves,
    Leaderboard,
    LeaderboardEntry,
    LeaderboardPlanner,
    Spread,
)

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

Cell = str | int | float | None
# Okabe-Ito, as on the website: distinguishable with the common colour-vision deficiencies.
PALETTE = ("#E69F00", "#56B4E9", "#009E73", "#0072B2", "#D55E00", "#CC79A7", "#F0E442",
           "#000000")
DASH = "–"
CURVE_POINTS = 1000  # per curve: plenty for a printed figure, small to fetch


class ReportError(RuntimeError):
    """The service could not be read."""


@dataclass(frozen=True)
class ReportData:
    """What the report is made of: the leaderboard of one preset, the curves of each area
    that has results, and every area's statistics."""

    preset: str
    board: Leaderboard
    areas: list[AreaOut]
    curves: dict[str, Curves] = field(default_factory=dict)
    source: str = ""


@dataclass(frozen=True)
class Table:
    name: str  # file stem
    title: str
    header: list[str]
    rows: list[list[Cell]]
    # The Markdown version: the website's cells ("mean (min–max)"); None: the CSV's own.
    markdown_header: list[str] | None = None
    markdown_rows: list[list[str]] | None = None


# -- the HTTP part ----------------------------------------------------------------------------

def _get(client: httpx.Client, path: str, params: dict[str, Any] | None = None) -> Any:
    try:
        response = client.get(path, params=params)
    except httpx.HTTPError as exc:
        raise ReportError(f"cannot reach the service: {exc}") from None
    if response.status_code != 200:
        raise ReportError(f"GET {path} answered {response.status_code}: {response.text[:200]}")
    return response.json()


def fetch_report_data(client: httpx.Client, preset: str = "default") -> ReportData:
    """Everything the report needs, from the API under `/api/v1` of `client`'s base URL."""
    board = Leaderboard.model_validate(_get(client, "/api/v1/leaderboard", {"preset": preset}))
    areas = [AreaOut.model_validate(a) for a in _get(client, "/api/v1/areas")]
    curves = {
        area: Curves.model_validate(_get(client, "/api/v1/curves", {
            "area": area, "preset": preset, "max_points": CURVE_POINTS}))
        for area in board.areas}
    return ReportData(preset=preset, board=board, areas=areas, curves=curves,
                      source=str(client.base_url))


# -- the tables -------------------------------------------------------------------------------

def _scaled(value: float | None, scale: float = 1.0) -> float | None:
    return None if value is None else round(value * scale, 6)


def _spread_cells(s: Spread, scale: float = 1.0) -> list[Cell]:
    return [_scaled(s.mean, scale), _scaled(s.min, scale), _scaled(s.max, scale)]


def _fmt(value: float | None, digits: int, scale: float = 1.0) -> str:
    return DASH if value is None else f"{value * scale:.{digits}f}"


def _spread_text(s: Spread, digits: int, scale: float = 1.0) -> str:
    if s.mean is None:
        return DASH
    return (f"{_fmt(s.mean, digits, scale)} ({_fmt(s.min, digits, scale)}{DASH}"
            f"{_fmt(s.max, digits, scale)})")


def _spread_header(label: str) -> list[str]:
    return [f"{label} mean", f"{label} min", f"{label} max"]


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
    header += ["average coverage %", "relative coverage %", "mean coverage rank",
               "mean F-score rank", "pareto"]
    md_header += ["Average", "Relative", "Avg. rank"]
    rows: list[list[Cell]] = []
    md_rows: list[list[str]] = []
    for p in board.overall:
        row: list[Cell] = [p.rank, p.planner, "yes" if p.builtin else "no"]
        md = [str(p.rank), p.planner + (" *" if p.pareto else "")]
        for area in board.areas:
            e = entries.get((p.planner, area))
            row += _spread_cells(e.coverage, 100) if e else [None, None, None]
            md.append(_spread_text(e.coverage, 1, 100) if e else DASH)
        row += [_scaled(p.mean_coverage, 100), _scaled(p.mean_relative_coverage, 100),
                _scaled(p.mean_coverage_rank), _scaled(p.mean_fscore_rank),
                "yes" if p.pareto else "no"]
        md += [_fmt(p.mean_coverage, 1, 100), _fmt(p.mean_relative_coverage, 1, 100),
               _fmt(p.mean_coverage_rank, 1)]
        rows.append(row)
        md_rows.append(md)
    return Table("table2", "Table 2: coverage per area, % (mean (min–max) over runs); "
                 "* marks the Pareto set", header, rows, md_header, md_rows)


def table3(board: Leaderboard) -> Table:
    """F-score (%) and RMSE (cm) of the final mesh per area, averages and the F-score rank."""
    entries = _entries(board)
    header = ["planner", "baseline"]
    md_header = ["Planner"]
    for area in board.areas:
        header += _spread_header(f"{area} F-score %") + _spread_header(f"{area} RMSE cm")
        md_header += [f"{area} F", f"{area} RMSE"]
    header += ["average F-score %", "average RMSE cm", "mean F-score rank"]
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
                row += [None] * 6
                md += [DASH, DASH]
                continue
            row += _spread_cells(e.fscore, 100) + _spread_cells(e.rmse_m, 100)
            md += [_spread_text(e.fscore, 1, 100), _spread_text(e.rmse_m, 2, 100)]
        row += [_scaled(p.mean_fscore, 100), _scaled(p.mean_rmse_m, 100),
                _scaled(p.mean_fscore_rank)]
        md += [_fmt(p.mean_fscore, 1, 100), _fmt(p.mean_rmse_m, 2, 100),
               _fmt(p.mean_fscore_rank, 1)]
        rows.append(row)
        md_rows.append(md)
    return Table("table3", "Table 3: surface reconstruction, F-score % and RMSE cm "
                 "(mean (min–max) over runs)", header, rows, md_header, md_rows)


def table4(board: Leaderboard) -> Table:
    """Per area and planner: iterations, planning time per iteration, path length, and the
    area's coverage and F-score with their ranks."""
    header = ["area", "planner", "runs", *_spread_header("iterations"),
              *_spread_header("planning time ms"), *_spread_header("path length m"),
              *_spread_header("coverage %"), *_spread_header("F-score %"), "collisions",
              "coverage rank", "F-score rank"]
    md_header = ["Area", "Planner", "Runs", "Iterations", "Planning time, ms",
                 "Path length, m", "Coverage, %", "F-score, %", "Collisions", "Coverage rank",
                 "F-score rank"]
    rows: list[list[Cell]] = []
    md_rows: list[list[str]] = []
    for area in board.areas:
        here = sorted((e for e in board.entries if e.area == area),
                      key=lambda e: (e.coverage_rank, e.planner))
        for e in here:
            rows.append([area, e.planner, e.runs, *_spread_cells(e.iterations),
                         *_spread_cells(e.planning_ms), *_spread_cells(e.path_length_m),
                         *_spread_cells(e.coverage, 100), *_spread_cells(e.fscore, 100),
                         e.collisions, e.coverage_rank, e.fscore_rank])
            md_rows.append([area, e.planner, str(e.runs), _spread_text(e.iterations, 0),
                            _spread_text(e.planning_ms, 1), _spread_text(e.path_length_m, 1),
                            _spread_text(e.coverage, 1, 100), _spread_text(e.fscore, 1, 100),
                            str(e.collisions), _fmt(e.coverage_rank, 1),
                            _fmt(e.fscore_rank, 1)])
    return Table("table4", "Table 4: planning per area: iterations, planning time per "
                 "iteration (median of a run), path length (mean (min–max) over runs)",
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


# -- the figures ------------------------------------------------------------------------------

def _figure(width: float, height: float) -> Figure:
    import matplotlib

    matplotlib.use("Agg")  # headless: no display is needed, nor wanted
    from matplotlib.figure import Figure

    return Figure(figsize=(width, height), layout="constrained")


def _colours(board: Leaderboard) -> dict[str, str]:
    names = [p.planner for p in board.overall]
    return {n: PALETTE[i % len(PALETTE)] for i, n in enumerate(sorted(names))}


def _nan(values: list[float | None]) -> list[float]:
    return [float("nan") if v is None else v for v in values]


def _band_plot(ax: Axes, t: list[float], band: Band, colour: str, label: str) -> None:
    ax.fill_between(t, _nan(band.min), _nan(band.max), color=colour, alpha=0.2, linewidth=0)
    ax.plot(t, _nan(band.mean), color=colour, label=label, linewidth=1.4)


def curves_figure(data: ReportData, which: str) -> Figure:
    """Figure 4 (`which="volume"`: explored volume) or 5 (`"recall"`: surface recall) over
    time, one panel per area with results, one line (mean) and band (min-max) per planner."""
    areas = list(data.curves)
    cols = max(1, min(4, len(areas)))
    rows = max(1, -(-len(areas) // cols))
    fig = _figure(3.6 * cols, 2.8 * rows + 0.6)
    colours = _colours(data.board)
    axes = fig.subplots(rows, cols, squeeze=False)
    for ax in axes.flat[len(areas):]:
        ax.set_visible(False)
    if not areas:
        axes[0, 0].set_visible(True)
        axes[0, 0].text(0.5, 0.5, "no results yet", ha="center", va="center")
        axes[0, 0].set_axis_off()
    for ax, area in zip(axes.flat, areas, strict=False):
        c = data.curves[area]
        for p in c.planners:
            if which == "volume":
                _band_plot(ax, p.time_s, p.explored_volume_m3, colours[p.planner], p.planner)
            else:
                _band_plot(ax, p.recall_time_s, p.surface_recall, colours[p.planner], p.planner)
        if c.plateau_s:
            ax.axvline(c.plateau_s, color="0.6", linestyle=":", linewidth=1)
        ax.set_title(area)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("explored volume (m³)" if which == "volume" else "surface recall")
        if which == "recall":
            ax.set_ylim(0.0, 1.0)
        ax.grid(alpha=0.3)
    handles, labels = [], []
    for ax in axes.flat:
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
    if handles:
        fig.legend(handles, labels, loc="outside lower center", ncols=min(len(labels), 4))
    title = ("Figure 4: explored volume over time" if which == "volume" else
             "Figure 5: surface recall over time")
    fig.suptitle(f"{title} (mean, min–max band over runs; preset {data.preset})")
    return fig


def pareto_figure(data: ReportData) -> Figure:
    """Figure 6: mean coverage rank against mean F-score rank (1 is best), the Pareto set
    circled and joined."""
    fig = _figure(5.5, 4.6)
    ax = fig.subplots()
    colours = _colours(data.board)
    ranked: list[LeaderboardPlanner] = [p for p in data.board.overall
                                        if p.mean_fscore_rank is not None]
    for p in ranked:
        assert p.mean_fscore_rank is not None
        ax.scatter([p.mean_coverage_rank], [p.mean_fscore_rank], color=colours[p.planner],
                   s=50, zorder=3, label=p.planner)
        ax.annotate(p.planner, (p.mean_coverage_rank, p.mean_fscore_rank),
                    textcoords="offset points", xytext=(6, 4), fontsize=8)
    front = sorted((p for p in ranked if p.pareto), key=lambda p: p.mean_coverage_rank)
    if front:
        xs = [p.mean_coverage_rank for p in front]
        ys = [float(p.mean_fscore_rank or 0.0) for p in front]
        ax.plot(xs, ys, color="black", linewidth=1, zorder=2)
        ax.scatter(xs, ys, s=160, facecolors="none", edgecolors="black", zorder=4,
                   label="Pareto set")
    if not ranked:
        ax.text(0.5, 0.5, "no results yet", ha="center", va="center", transform=ax.transAxes)
    ax.set_xlabel("mean coverage rank (1 is best)")
    ax.set_ylabel("mean F-score rank (1 is best)")
    ax.invert_xaxis()
    ax.invert_yaxis()
    ax.grid(alpha=0.3)
    ax.set_title(f"Figure 6: coverage rank vs F-score rank (preset {data.preset})")
    return fig


def _save(fig: Figure, out: Path, stem: str) -> list[Path]:
    paths = []
    for suffix in ("png", "svg"):
        path = out / f"{stem}.{suffix}"
        # No date in the SVG: the same data gives the same file.
        fig.savefig(path, format=suffix, dpi=150,
                    metadata={"Date": None} if suffix == "svg" else None)
        paths.append(path)
    return paths


FIGURES: dict[str, tuple[str, Callable[[ReportData], Figure]]] = {
    "figure4": ("Figure 4: explored volume over time",
                lambda d: curves_figure(d, "volume")),
    "figure5": ("Figure 5: surface recall over time", lambda d: curves_figure(d, "recall")),
    "figure6": ("Figure 6: coverage rank vs F-score rank", pareto_figure),
}


# -- the whole report -------------------------------------------------------------------------

def write_report(data: ReportData, out: Path) -> list[Path]:
    """Write `table1..4.csv`, `report.md` and `figure4..6.{png,svg}` into `out` (created if
    missing); returns the paths written."""
    out.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    parts = [f"# FLYBO report, preset `{data.preset}`", ""]
    if data.source:
        parts += [f"From {data.source}. Every cell is the mean over the succeeded runs, with "
                  "the smallest and largest run in brackets.", ""]
    for table in tables(data):
        path = out / f"{table.name}.csv"
        write_csv(table, path)
        written.append(path)
        parts += [f"## {table.title}", "", markdown_table(table), "",
                  f"CSV: [{path.name}]({path.name})", ""]
    for stem, (title, draw) in FIGURES.items():
        written += _save(draw(data), out, stem)
        parts += [f"## {title}", "", f"![{title}]({stem}.png)", "",
                  f"SVG: [{stem}.svg]({stem}.svg)", ""]
    md = out / "report.md"
    md.write_text("\n".join(parts), encoding="utf-8")
    written.append(md)
    return written
