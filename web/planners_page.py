"""Planner pages: the list, and one planner's description, config, versions and results (per
preset and benchmark version: results of different benchmark versions are never ranked
together)."""

from __future__ import annotations

import json
from urllib.parse import urlencode

from fastapi import APIRouter, Request
from fastapi.responses import HTMLResponse
from sqlalchemy import select

from server.benchmark_versions import current_version
from server.catalog import CatalogError, find_planner
from server.deps import SessionDep
from server.leaderboard import build_leaderboard
from server.models import AreaRow, Job, PlannerRow, Run, RunResult, RunState, User
from web.html import (
    DASH,
    esc,
    not_found,
    num,
    page,
    planner_link,
    spread_td,
    status_badge,
    table,
    td,
)

router = APIRouter(include_in_schema=False)
# What a planner is to its reference's method (`planners.fidelity`), as the planner page says it.
_METHODS = {
    "original": "original: the method as its paper published it",
    "variant": "variant: it differs from the method its paper published (docs/planners.md)",
}
MAX_RUNS = 200


@router.get("/planners", response_class=HTMLResponse)
def planners_page(session: SessionDep) -> HTMLResponse:
    found = session.execute(select(PlannerRow, User.name).outerjoin(
        User, PlannerRow.owner_id == User.id).order_by(PlannerRow.name, PlannerRow.version))
    rows = [f"<tr>{td(planner_link(r.key, r.builtin, r.method), r.key)}{td(esc(owner or DASH))}"
            f"{td(esc(r.description))}{td(esc(r.reference))}</tr>" for r, owner in found]
    body = ("<h1>Planners</h1>"
            + table("Registered planners and their versions",
                    [("Planner", ""), ("Owner", ""), ("Description", ""), ("Reference", "")],
                    rows, empty="No planners are registered."))
    return page("Planners", body, scripts=("sort.js",), current="/planners")


def _runs_table(session: SessionDep, planner_id: int) -> str:
    found = session.execute(
        select(Run, AreaRow.name, RunResult).join(Job, Run.job_id == Job.id)
        .join(AreaRow, Run.area_id == AreaRow.id)
        .outerjoin(RunResult, RunResult.run_id == Run.id)
        .where(Job.planner_id == planner_id).order_by(Run.id.desc()).limit(MAX_RUNS))
    rows = []
    for run, area, result in found:
        r = result
        rows.append("<tr>" + "".join([
            td(f"<a href='/runs/{run.id}'>{run.id}</a>", run.id, "num"),
            td(f"<a href='/jobs/{run.job_id}'>{run.job_id}</a>", run.job_id, "num"),
            td(esc(area), area), td(str(run.seed), run.seed, "num"), td(esc(run.preset)),
            td(status_badge(run.status), run.status),
            td(num(r.coverage if r else None, 1, 100), r.coverage if r else None, "num"),
            td(num(r.fscore if r else None, 1, 100), r.fscore if r else None, "num"),
            td(num(r.rmse_m if r else None, 2, 100), r.rmse_m if r else None, "num"),
            td(num(r.path_length_m if r else None, 1), r.path_length_m if r else None, "num"),
            td(esc(r.benchmark_version) if r else DASH, r.benchmark_version if r else None),
        ]) + "</tr>")
    return table(f"Runs (newest {MAX_RUNS})", [
        ("Run", ""), ("Job", ""), ("Area", ""), ("Seed", ""), ("Preset", ""), ("Status", ""),
        ("Coverage, %", ""), ("F-score, %", ""), ("RMSE, cm", ""), ("Path, m", ""),
        ("Benchmark version", "the benchmark version the run was made with")],
        rows, table_id="runs-table", empty="No runs yet.")


def _results(session: SessionDep, key: str, boards: list[tuple[str, str]],
             current: str) -> str:
    """One table per (preset, benchmark version) the planner has succeeded runs in."""
    parts = []
    for preset, version in boards:
        board = build_leaderboard(session, preset, benchmark_version=version)
        mine = [e for e in board.entries if e.planner == key]
        overall = next((p for p in board.overall if p.planner == key), None)

        def link(area: str, preset: str = preset, version: str = version) -> str:
            query = urlencode({"preset": preset, "area": area, "benchmark_version": version})
            return f"<a href='/?{esc(query)}'>{esc(area)}</a>"

        rows = ["<tr>" + "".join([
            td(link(e.area), e.area), td(str(e.runs), e.runs, "num"),
            spread_td(e.coverage, 1, 100),
            spread_td(e.fscore, 1, 100), spread_td(e.rmse_m, 2, 100),
            td(num(e.coverage_rank, 1), e.coverage_rank, "num"),
            td(num(e.fscore_rank, 1), e.fscore_rank, "num")]) + "</tr>" for e in mine]
        rank = f"overall rank {overall.rank} of {len(board.overall)}" if overall else ""
        label = f"{version} (current)" if version == current else version
        parts.append(table(f"Preset {preset}, benchmark version {label}: {rank}", [
            ("Area", ""), ("Runs", ""), ("Coverage, %", ""), ("F-score, %", ""),
            ("RMSE, cm", ""), ("Coverage rank", ""), ("F-score rank", "")], rows))
    return "".join(parts) or "<p>No succeeded runs yet.</p>"


@router.get("/planners/{name}", response_class=HTMLResponse)
def planner_page(name: str, request: Request, session: SessionDep) -> HTMLResponse:
    try:
        row = find_planner(session, name)
    except CatalogError:
        return not_found(f"No planner named {name}.")
    owner = session.get(User, row.owner_id) if row.owner_id is not None else None
    versions = session.scalars(select(PlannerRow).where(PlannerRow.name == row.name)
                               .order_by(PlannerRow.version)).all()
    links = ", ".join(f"<a href='/planners/{esc(v.key)}'"
                      f"{' aria-current=page' if v.id == row.id else ''}>{esc(v.key)}</a>"
                      for v in versions)
    current = current_version(request.app.state, session)
    boards = sorted({(preset, version) for preset, version in session.execute(
        select(Run.preset, RunResult.benchmark_version).join(Job, Run.job_id == Job.id)
        .join(RunResult, RunResult.run_id == Run.id)
        .where(Job.planner_id == row.id, Run.status == RunState.SUCCEEDED.value).distinct()
    )}, key=lambda pv: (pv[0], pv[1] != current, pv[1]))
    config = json.dumps(row.config.get("defaults", row.config), indent=2, sort_keys=True)
    body = (
        f"<h1>{esc(row.key)}{' <span class=badge>baseline</span>' if row.builtin else ''}</h1>"
        f"<p class='lead'>{esc(row.description) or 'No description.'}</p>"
        "<dl class='facts'>"
        f"<dt>Reference</dt><dd>{esc(row.reference) or DASH}</dd>"
        f"<dt>Method</dt><dd>{_METHODS.get(row.method, 'not stated')}</dd>"
        f"<dt>Owner</dt><dd>{esc(owner.name) if owner else 'built in'}</dd>"
        f"<dt>Versions</dt><dd>{links}</dd>"
        f"<dt>Code hash</dt><dd><code>{esc(row.code_hash) or DASH}</code></dd></dl>"
        f"<h2>Configuration (defaults)</h2><pre class='config'>{esc(config)}</pre>"
        f"<h2>Results</h2>{_results(session, row.key, boards, current)}"
        f"{_runs_table(session, row.id)}")
    return page(row.key, body, scripts=("sort.js",), current="/planners")
