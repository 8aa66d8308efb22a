"""The front page: the leaderboard of one preset as the paper's Tables 2, 3 and 4, and its plots.

The tables are rendered here, on the server, so the page paints at once; the figures are drawn
by `leaderboard.js` from `/api/v1/curves` (Figures 4 and 5) and from the `data-*` ranks of the
overall table (Figure 6), so they cost no second leaderboard query.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query
from fastapi.responses import HTMLResponse
from sqlalchemy import select

from server.catalog import preset_names
from server.deps import SessionDep
from server.leaderboard import build_leaderboard
from server.models import Run
from server.schemas import Leaderboard, LeaderboardEntry, LeaderboardPlanner
from web.html import DASH, esc, num, options, page, planner_link, spread_td, table, td
from web.jobs_page import recent_jobs_table

router = APIRouter(include_in_schema=False)
RECENT_JOBS = 10


def _presets(session: SessionDep) -> list[str]:
    stored = set(session.scalars(select(Run.preset).distinct()))
    return sorted(stored | set(preset_names()))


def _entry_map(board: Leaderboard) -> dict[tuple[str, str], LeaderboardEntry]:
    return {(e.planner, e.area): e for e in board.entries}


def _rank(value: float | None) -> str:
    return td(num(value, 1), value, "num")


def _coverage_table(board: Leaderboard) -> str:
    """Table 2: coverage per area (mean, with min-max over runs), averages and rank."""
    entries = _entry_map(board)
    headers = [("Rank", "by mean coverage rank"), ("Planner", "")]
    headers += [(esc(a), f"coverage on {a}, %") for a in board.areas]
    headers += [("Average", "mean coverage over areas, %"),
                ("Relative", "mean relative coverage (the paper's: volume at the plateau over "
                             "the best planner's), %"),
                ("Avg. rank", "mean per-area coverage rank")]
    rows = []
    for p in board.overall:
        cells = [td(str(p.rank), p.rank, "num"), td(planner_link(p.planner, p.builtin), p.planner)]
        for area in board.areas:
            e = entries.get((p.planner, area))
            cells.append(spread_td(e.coverage, 1, 100) if e else td(DASH))
        cells += [td(num(p.mean_coverage, 1, 100), p.mean_coverage, "num"),
                  td(num(p.mean_relative_coverage, 1, 100), p.mean_relative_coverage, "num"),
                  _rank(p.mean_coverage_rank)]
        rows.append(_overall_row(p, cells))
    return table("Table 2: coverage per area, % (mean; min–max over runs)", headers, rows,
                 table_id="coverage-table", empty="No results yet.")


def _overall_row(p: LeaderboardPlanner, cells: list[str]) -> str:
    # The ranks ride along as data attributes: leaderboard.js draws Figure 6 from them.
    fs_rank = "" if p.mean_fscore_rank is None else f"{p.mean_fscore_rank:.6g}"
    return (f"<tr data-planner='{esc(p.planner)}' data-coverage-rank='{p.mean_coverage_rank:.6g}'"
            f" data-fscore-rank='{fs_rank}' data-pareto='{'1' if p.pareto else '0'}'>"
            f"{''.join(cells)}</tr>")


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
        cells = [td(planner_link(p.planner, p.builtin), p.planner)]
        for area in board.areas:
            e = entries.get((p.planner, area))
            cells += [spread_td(e.fscore, 1, 100), spread_td(e.rmse_m, 2, 100)] if e else [
                td(DASH), td(DASH)]
        cells += [td(num(p.mean_fscore, 1, 100), p.mean_fscore, "num"),
                  td(num(p.mean_rmse_m, 2, 100), p.mean_rmse_m, "num"),
                  _rank(p.mean_fscore_rank)]
        rows.append(f"<tr>{''.join(cells)}</tr>")
    return table("Table 3: surface reconstruction, F-score % and RMSE cm (mean; min–max)",
                 headers, rows, table_id="surface-table", empty="No results yet.")


def _area_table(board: Leaderboard, area: str | None) -> str:
    """Table 4 for one area: iterations, planning time per iteration, path length."""
    here = [e for e in board.entries if e.area == area]
    headers = [("Planner", ""), ("Runs", "succeeded runs"), ("Iterations", "plan calls"),
               ("Planning time, ms", "median wall time of a plan call"),
               ("Path length, m", "flown path"), ("Coverage, %", ""), ("F-score, %", ""),
               ("Collisions", "over all runs"), ("Coverage rank", ""), ("F-score rank", "")]
    rows = [
        "<tr>" + "".join([
            td(planner_link(e.planner, e.builtin), e.planner), td(str(e.runs), e.runs, "num"),
            spread_td(e.iterations, 0), spread_td(e.planning_ms, 1),
            spread_td(e.path_length_m, 1), spread_td(e.coverage, 1, 100),
            spread_td(e.fscore, 1, 100), td(str(e.collisions), e.collisions, "num"),
            _rank(e.coverage_rank), _rank(e.fscore_rank)]) + "</tr>"
        for e in sorted(here, key=lambda e: e.coverage_rank)]
    return table(f"Table 4: planning on {area or DASH} (mean; min–max over runs)", headers, rows,
                 table_id="area-table", empty="No results on this area yet.")


def _controls(presets: list[str], preset: str, areas: list[str], area: str | None) -> str:
    return (
        "<form class='controls' method='get' action='/' data-autosubmit>"
        f"<label for='preset'>Preset</label><select id='preset' name='preset'>"
        f"{options(presets, preset)}</select>"
        f"<label for='area'>Area for Table 4 and the curves</label><select id='area' "
        f"name='area'>{options(areas, area)}</select>"
        "<button type='submit'>Show</button></form>")


def _figures(preset: str, area: str | None) -> str:
    if area is None:
        return ""
    data = f"data-preset='{esc(preset)}' data-area='{esc(area)}'"
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
        "coverage rank against mean F-score rank (1 is best); the Pareto set is joined by a line."
        " Ranks are in Tables 2 and 3.</figcaption></figure>"
        "</div></section>")


@router.get("/", response_class=HTMLResponse)
def leaderboard_page(
    session: SessionDep,
    preset: Annotated[str, Query(max_length=32)] = "default",
    area: Annotated[str | None, Query(max_length=40)] = None,
) -> HTMLResponse:
    board = build_leaderboard(session, preset)
    chosen = area if area in board.areas else (board.areas[0] if board.areas else None)
    pareto = ", ".join(p.planner for p in board.overall if p.pareto) or DASH
    body = (
        "<h1>Leaderboard</h1>"
        f"<p class='lead'>Exploration planners on simulated areas, preset <code>{esc(preset)}"
        f"</code>. Every figure is the mean over succeeded runs; the small numbers give the "
        "smallest and largest run. Built-in planners are marked <span class='badge'>baseline"
        "</span>. Click a column header to sort.</p>"
        f"{_controls(_presets(session), preset, board.areas, chosen)}"
        f"{_coverage_table(board)}"
        f"<p>Pareto set (coverage rank against F-score rank): <strong id='pareto-set'>"
        f"{esc(pareto)}</strong></p>"
        f"{_surface_table(board)}{_area_table(board, chosen)}{_figures(preset, chosen)}"
        f"<h2>Jobs</h2>{recent_jobs_table(session, RECENT_JOBS)}"
        "<p><a href='/jobs'>All jobs</a></p>")
    return page("Leaderboard", body, scripts=("sort.js", "autosubmit.js", "leaderboard.js"),
                charts=chosen is not None, current="/")
