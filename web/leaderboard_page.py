"""The front page: the leaderboard of one preset and one benchmark version as the paper's Tables
2, 3 and 4, and its plots.

The tables are rendered here, on the server, so the page paints at once; the figures are drawn
by `leaderboard.js` from `/api/v1/curves` (Figures 4 and 5) and from the `data-*` ranks of the
overall table (Figure 6), so they cost no second leaderboard query. Results of different
benchmark versions are never ranked together: the page shows the current version's unless a
link of its version selector (`?benchmark_version=`) asks for another. Besides the paper's
columns, the tables show each leaderboard metric of the measures (`Leaderboard.metrics`). The
public areas rank on the main tables; the held-out areas on a board of their own, with each
planner's gap between the two (`web.heldout_board`).
"""

from __future__ import annotations

import re
from typing import Annotated
from urllib.parse import urlencode

from fastapi import APIRouter, Query, Request
from fastapi.responses import HTMLResponse
from sqlalchemy import select

from server.benchmark_versions import (
    UnknownBenchmarkVersionError,
    check_known,
    current_version,
    version_counts,
)
from server.catalog import preset_names
from server.deps import SessionDep
from server.leaderboard import build_leaderboard
from server.models import Run
from server.schemas import (
    Interval,
    Leaderboard,
    LeaderboardEntry,
    LeaderboardPlanner,
    MetricOut,
)
from web.heldout_board import heldout_section
from web.html import (
    DASH,
    ci_span,
    esc,
    not_found,
    num,
    options,
    page,
    planner_link,
    spread_td,
    table,
    td,
)
from web.jobs_page import recent_jobs_table

router = APIRouter(include_in_schema=False)
RECENT_JOBS = 10
# Leaderboard metrics the paper's columns already show; the others get columns of their own.
SHOWN_METRICS = frozenset({"coverage", "fscore", "rmse_m"})


def _presets(session: SessionDep) -> list[str]:
    stored = set(session.scalars(select(Run.preset).distinct()))
    return sorted(stored | set(preset_names()))


def _extra_metrics(board: Leaderboard) -> list[MetricOut]:
    return [m for m in board.metrics if m.key not in SHOWN_METRICS]


def _digits(fmt: str) -> int:
    """The decimals of a format spec such as '.3f' (0 for 'd' and the like)."""
    precision = re.search(r"\.(\d+)", fmt)
    return int(precision.group(1)) if precision else 0


def _metric_header(m: MetricOut, what: str) -> tuple[str, str]:
    unit = f", {m.unit}" if m.unit else ""
    better = "lower" if not m.higher_is_better else "higher"
    return (f"{esc(m.label)}{esc(unit)}", f"{what}; {better} is better; runs where it is "
                                          "undefined are left out")


def _entry_map(board: Leaderboard) -> dict[tuple[str, str], LeaderboardEntry]:
    return {(e.planner, e.area): e for e in board.entries}


def _mean_td(value: float | None, interval: Interval | None, digits: int,
             scale: float = 1.0) -> str:
    ci = "" if interval is None else ci_span(interval.low, interval.high, digits, scale)
    return td(f"{num(value, digits, scale)}{ci}", value, "num")


def _coverage_table(board: Leaderboard) -> str:
    """Table 2: coverage per area (mean, with min-max over runs), averages and rank."""
    entries = _entry_map(board)
    headers = [("Rank", "by mean coverage rank; planners whose intervals of it overlap share a "
                        "rank (docs/statistics.md)"), ("Planner", "")]
    headers += [(esc(a), f"coverage on {a}, %") for a in board.areas]
    headers += [("Average", "mean coverage over areas, %"),
                ("Relative", "mean relative coverage (the paper's: volume at the plateau over "
                             "the best planner's), %"),
                ("Avg. rank", "mean per-area coverage rank")]
    extra = _extra_metrics(board)
    headers += [_metric_header(m, f"mean over areas of the per-area mean {m.label}")
                for m in extra]
    rows = []
    for p in board.overall:
        cells = [td(str(p.rank), p.rank, "num"),
                 td(planner_link(p.planner, p.builtin, p.method), p.planner)]
        for area in board.areas:
            e = entries.get((p.planner, area))
            cells.append(spread_td(e.coverage, 1, 100) if e else td(DASH))
        cells += [_mean_td(p.mean_coverage, p.mean_coverage_ci, 1, 100),
                  _mean_td(p.mean_relative_coverage, p.mean_relative_coverage_ci, 1, 100),
                  _mean_td(p.mean_coverage_rank, p.mean_coverage_rank_ci, 1)]
        for m in extra:
            value = p.mean_metrics.get(m.key)
            cells.append(td(num(value, _digits(m.fmt)), value, "num"))
        rows.append(_overall_row(p, cells))
    return table("Table 2: coverage per area, % (mean; [95 % interval]; min–max over runs)",
                 headers, rows,
                 table_id="coverage-table", empty="No results yet.")


def _overall_row(p: LeaderboardPlanner, cells: list[str]) -> str:
    # The ranks ride along as data attributes: leaderboard.js draws Figure 6 from them.
    fs_rank = "" if p.mean_fscore_rank is None else f"{p.mean_fscore_rank:.6g}"
    return (f"<tr data-planner='{esc(p.planner)}' data-coverage-rank='{p.mean_coverage_rank:.6g}'"
            f" data-fscore-rank='{fs_rank}' data-pareto='{'1' if p.pareto else '0'}'"
            f"{_interval_data('coverage-rank', p.mean_coverage_rank_ci)}"
            f"{_interval_data('fscore-rank', p.mean_fscore_rank_ci)}>{''.join(cells)}</tr>")


def _interval_data(name: str, interval: Interval | None) -> str:
    """The interval's bounds as data attributes (Figure 6 draws them as error bars)."""
    if interval is None:
        return ""
    return f" data-{name}-low='{interval.low:.6g}' data-{name}-high='{interval.high:.6g}'"


def _surface_table(board: Leaderboard) -> str:
    """Table 3: F-score and RMSE per area with spread, averages and the F-score rank."""
    entries = _entry_map(board)
    headers = [("Planner", "")]
    for a in board.areas:
        headers += [(f"{esc(a)} F", f"F-score of the final mesh on {a}, %"),
                    (f"{esc(a)} RMSE", f"RMSE of the final mesh on {a}, cm")]
    headers += [("Avg. F", "mean F-score over areas, %"), ("Avg. RMSE", "cm"),
                ("Avg. F rank", "mean per-area F-score rank")]
    rows = []
    by_fscore = sorted(board.overall, key=lambda p: (p.mean_fscore_rank is None,
                                                     p.mean_fscore_rank or 0.0))
    for p in by_fscore:
        cells = [td(planner_link(p.planner, p.builtin, p.method), p.planner)]
        for area in board.areas:
            e = entries.get((p.planner, area))
            cells += [spread_td(e.fscore, 1, 100), spread_td(e.rmse_m, 2, 100)] if e else [
                td(DASH), td(DASH)]
        cells += [_mean_td(p.mean_fscore, p.mean_fscore_ci, 1, 100),
                  td(num(p.mean_rmse_m, 2, 100), p.mean_rmse_m, "num"),
                  _mean_td(p.mean_fscore_rank, p.mean_fscore_rank_ci, 1)]
        rows.append(f"<tr>{''.join(cells)}</tr>")
    return table("Table 3: surface reconstruction, F-score % and RMSE cm (mean; [95 % "
                 "interval]; min–max)",
                 headers, rows, table_id="surface-table", empty="No results yet.")


def _area_table(board: Leaderboard, area: str | None) -> str:
    """Table 4 for one area: iterations, planning time per iteration, path length."""
    here = [e for e in board.entries if e.area == area]
    headers = [("Planner", ""), ("Runs", "succeeded runs"), ("Iterations", "plan calls"),
               ("Planning time, ms", "median wall time of a plan call"),
               ("Path length, m", "flown path"), ("Coverage, %", ""), ("F-score, %", ""),
               ("Collisions", "over all runs"),
               ("Coverage rank", "the rank of its tie group: planners whose coverage intervals "
                                 "overlap share it"),
               ("F-score rank", "the same by F-score")]
    extra = _extra_metrics(board)
    headers += [_metric_header(m, f"{m.label} over the runs") for m in extra]
    rows = [
        "<tr>" + "".join([
            td(planner_link(e.planner, e.builtin, e.method), e.planner),
            td(str(e.runs), e.runs, "num"),
            spread_td(e.iterations, 0), spread_td(e.planning_ms, 1),
            spread_td(e.path_length_m, 1), spread_td(e.coverage, 1, 100),
            spread_td(e.fscore, 1, 100), td(str(e.collisions), e.collisions, "num"),
            _group(e.coverage_group_rank, e.coverage_rank),
            _group(e.fscore_group_rank, e.fscore_rank),
            *(spread_td(e.metrics[m.key], _digits(m.fmt)) if m.key in e.metrics else td(DASH)
              for m in extra)]) + "</tr>"
        for e in sorted(here, key=lambda e: e.coverage_rank)]
    return table(f"Table 4: planning on {area or DASH} (mean; min–max over runs)", headers, rows,
                 table_id="area-table", empty="No results on this area yet.")


def _group(rank: int | None, paper: float | None) -> str:
    """A tie group's rank, with the paper's rank by the mean alone in its tooltip."""
    if rank is None:
        return td(DASH)
    return td(f"<span title='by the mean alone: {num(paper, 1)}'>{rank}</span>", rank, "num")


def _controls(presets: list[str], preset: str, areas: list[str], area: str | None,
              version: str | None) -> str:
    """`version`: the benchmark version shown when it is not the current one (kept by the
    form)."""
    keep = ("" if version is None else
            f"<input type='hidden' name='benchmark_version' value='{esc(version)}'>")
    return (
        "<form class='controls' method='get' action='/' data-autosubmit>"
        f"<label for='preset'>Preset</label><select id='preset' name='preset'>"
        f"{options(presets, preset)}</select>"
        f"<label for='area'>Area for Table 4 and the curves</label><select id='area' "
        f"name='area'>{options(areas, area)}</select>{keep}"
        "<button type='submit'>Show</button></form>")


def _versions(counts: list[tuple[str, int]], current: str, shown: str, preset: str,
              area: str | None) -> str:
    """The version selector: a link per benchmark version with results in this preset (and the
    current and shown ones), each to this page of that version."""
    runs = dict(counts)
    names = [current, *(v for v, _ in counts if v != current)]
    if shown not in names:
        names.append(shown)
    items = []
    for name in names:
        query = {"preset": preset, **({"area": area} if area else {}),
                 "benchmark_version": name}
        here = " aria-current='page'" if name == shown else ""
        notes = [f"{runs.get(name, 0)} run{'' if runs.get(name, 0) == 1 else 's'}"]
        if name == current:
            notes.append("current")
        items.append(f"<li><a href='/?{esc(urlencode(query))}'{here}>{esc(name)}</a> "
                     f"<small>{esc(', '.join(notes))}</small></li>")
    return ("<nav class='versions' aria-label='Benchmark versions' id='benchmark-versions'>"
            "<p>Benchmark version (results of different versions are never ranked together):"
            f"</p><ul>{''.join(items)}</ul></nav>")


def _figures(preset: str, area: str | None, version: str) -> str:
    if area is None:
        return ""
    data = (f"data-preset='{esc(preset)}' data-area='{esc(area)}' "
            f"data-benchmark-version='{esc(version)}'")
    return (
        "<section aria-labelledby='plots'><h2 id='plots'>Plots</h2><div class='figures'>"
        f"<figure><div class='chart' id='volume-chart' {data} role='img' "
        f"aria-label='Explored volume over time on {esc(area)}'></div><figcaption>Figure 4: "
        f"explored volume over time on {esc(area)}, mean per planner with its min–max band."
        "</figcaption></figure>"
        f"<figure><div class='chart' id='recall-chart' {data} role='img' "
        f"aria-label='Surface recall over time on {esc(area)}'></div><figcaption>Figure 5: "
        f"surface recall over time on {esc(area)}, mean with min–max band.</figcaption>"
        "</figure>"
        "<figure><div class='chart' id='pareto-chart' data-source='coverage-table' role='img' "
        "aria-label='Coverage rank against F-score rank'></div><figcaption>Figure 6: mean "
        "coverage rank against mean F-score rank (1 is best), with their 95 % intervals as "
        "error bars; the Pareto set is joined by a line. Ranks are in Tables 2 and 3."
        "</figcaption></figure>"
        "</div></section>")


@router.get("/", response_class=HTMLResponse)
def leaderboard_page(
    request: Request,
    session: SessionDep,
    preset: Annotated[str, Query(max_length=32)] = "default",
    area: Annotated[str | None, Query(max_length=40)] = None,
    benchmark_version: Annotated[str | None, Query(max_length=64)] = None,
) -> HTMLResponse:
    current = current_version(request.app.state, session)
    version = benchmark_version or current
    try:
        check_known(session, version, current)
    except UnknownBenchmarkVersionError as exc:
        return not_found(f"No results of benchmark version {version}. Known versions: "
                         f"{', '.join(exc.known)}.")
    board = build_leaderboard(session, preset, benchmark_version=version)
    chosen = area if area in board.areas else (board.areas[0] if board.areas else None)
    pareto = ", ".join(p.planner for p in board.overall if p.pareto) or DASH
    controls = _controls(_presets(session), preset, board.areas, chosen,
                         None if version == current else version)
    body = (
        "<h1>Leaderboard</h1>"
        f"<p class='lead'>Exploration planners on simulated areas, preset <code>{esc(preset)}"
        f"</code>, benchmark version <code id='benchmark-version'>{esc(version)}</code>"
        f"{' (current)' if version == current else ''}. Every figure is the mean over "
        "succeeded runs, with its 95 % confidence interval in brackets and the smallest and "
        "largest run below; planners whose intervals cannot be told apart share a rank "
        "(<a href='/docs'>API</a>: <code>statistics</code>). Built-in "
        "planners are marked <span class='badge'>baseline</span>. Click a column header to "
        "sort.</p>"
        f"{_versions(version_counts(session, preset), current, version, preset, chosen)}"
        f"{controls}"
        f"{_coverage_table(board)}"
        f"<p>Pareto set (coverage rank against F-score rank): <strong id='pareto-set'>"
        f"{esc(pareto)}</strong></p>"
        f"{heldout_section(session, preset, version)}"
        f"{_surface_table(board)}{_area_table(board, chosen)}"
        f"{_figures(preset, chosen, version)}"
        f"<h2>Jobs</h2>{recent_jobs_table(session, RECENT_JOBS)}"
        "<p><a href='/jobs'>All jobs</a></p>")
    return page("Leaderboard", body, scripts=("sort.js", "autosubmit.js", "leaderboard.js"),
                charts=chosen is not None, current="/")
