"""Job pages: recent jobs, and one job with the live progress of each run.

The job page is rendered complete; `job.js` then polls `GET /api/v1/jobs/{id}` every 2 s and
updates the progress bars and states in place until every run has reached a final state.
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Query
from fastapi.responses import HTMLResponse
from sqlalchemy import func, select
from sqlalchemy.orm import selectinload

from server.deps import SessionDep
from server.jobs import job_out
from server.models import FINAL_STATES, Job, Run
from server.schemas import JobOut
from web.html import esc, not_found, page, planner_link, status_badge, table, td

router = APIRouter(include_in_schema=False)
PAGE_SIZE = 50


def _eager() -> list[Any]:
    """What `job_out` reads, loaded up front rather than one query per run."""
    return [selectinload(Job.runs).selectinload(Run.area), selectinload(Job.planner),
            selectinload(Job.user)]


def progress_bar(value: float, label: str) -> str:
    pct = f"{value * 100:.0f}"
    return (f"<progress max='1' value='{value:.4f}' aria-label='{esc(label)}' data-progress>"
            f"{pct}%</progress> <span class='pct' data-pct>{pct}%</span>")


def _job_row(job: JobOut) -> str:
    return "<tr>" + "".join([
        td(f"<a href='/jobs/{job.id}'>{job.id}</a>", job.id, "num"),
        td(planner_link(job.planner, False), job.planner), td(esc(", ".join(job.areas))),
        td(str(job.runs_per_area), job.runs_per_area, "num"), td(esc(job.preset)),
        td(status_badge(job.status), job.status),
        td(progress_bar(job.progress, f"job {job.id}"), job.progress),
        td(esc(job.owner)), td(esc(job.created_at.strftime("%Y-%m-%d %H:%M UTC")),
                               job.created_at.isoformat())]) + "</tr>"


def recent_jobs_table(session: SessionDep, limit: int, offset: int = 0,
                      caption: str = "Recent jobs") -> str:
    jobs = session.scalars(select(Job).order_by(Job.id.desc()).limit(limit).offset(offset)
                           .options(*_eager())).all()
    return table(caption, [
        ("Job", ""), ("Planner", ""), ("Areas", ""), ("Runs per area", ""), ("Preset", ""),
        ("Status", ""), ("Progress", ""), ("Owner", ""), ("Created", "")],
        [_job_row(job_out(j)) for j in jobs], empty="No jobs yet.")


@router.get("/jobs", response_class=HTMLResponse)
def jobs_page(session: SessionDep,
              offset: Annotated[int, Query(ge=0, le=10_000_000)] = 0) -> HTMLResponse:
    total = session.scalar(select(func.count(Job.id))) or 0
    shown = max(0, min(PAGE_SIZE, total - offset))
    links = []
    if offset > 0:
        links.append(f"<a href='/jobs?offset={max(0, offset - PAGE_SIZE)}'>Newer</a>")
    if offset + PAGE_SIZE < total:
        links.append(f"<a href='/jobs?offset={offset + PAGE_SIZE}'>Older</a>")
    body = ("<h1>Jobs</h1><p class='lead'>Submit jobs with <code>flybo submit</code> or "
            "<code>POST /api/v1/jobs</code>.</p>"
            + recent_jobs_table(session, PAGE_SIZE, offset, f"Jobs {offset + 1 if shown else 0}"
                                f"–{offset + shown} of {total}")
            + f"<nav class='pager' aria-label='Pages'>{' · '.join(links)}</nav>")
    return page("Jobs", body, scripts=("sort.js",), current="/jobs")


@router.get("/jobs/{job_id}", response_class=HTMLResponse)
def job_page(job_id: str, session: SessionDep) -> HTMLResponse:
    job = None
    if job_id.isdigit() and len(job_id) < 12:  # not an int: an HTML 404, not a JSON 422
        job = session.scalar(select(Job).where(Job.id == int(job_id)).options(*_eager()))
    if job is None:
        return not_found(f"No job with id {job_id}.")
    out = job_out(job)
    rows = [f"<tr data-run='{r.id}'>" + "".join([
        td(f"<a href='/runs/{r.id}'>{r.id}</a>", r.id, "num"), td(esc(r.area), r.area),
        td(str(r.seed), r.seed, "num"), td(status_badge(r.status), r.status),
        td(progress_bar(r.progress, f"run {r.id}"), r.progress)]) + "</tr>" for r in out.runs]
    final = "1" if out.status in FINAL_STATES else "0"
    body = (
        f"<h1>Job {out.id}</h1>"
        f"<div id='job' data-job='{out.id}' data-final='{final}'>"
        "<dl class='facts'>"
        f"<dt>Planner</dt><dd>{planner_link(out.planner, False)}</dd>"
        f"<dt>Areas</dt><dd>{esc(', '.join(out.areas))}</dd>"
        f"<dt>Runs per area</dt><dd>{out.runs_per_area}</dd>"
        f"<dt>Preset</dt><dd>{esc(out.preset)}</dd>"
        f"<dt>Simulated seconds</dt><dd>{esc(out.seconds or 'the plateau time')}</dd>"
        f"<dt>Owner</dt><dd>{esc(out.owner)}</dd>"
        f"<dt>Created</dt><dd>{esc(out.created_at.strftime('%Y-%m-%d %H:%M:%S UTC'))}</dd>"
        + (f"<dt>Re-run of</dt><dd><a href='/jobs/{out.rerun_of}'>job {out.rerun_of}</a></dd>"
           if out.rerun_of else "")
        + f"<dt>Status</dt><dd id='job-status'>{status_badge(out.status)}</dd>"
        f"<dt>Progress</dt><dd id='job-progress'>{progress_bar(out.progress, 'job')}</dd></dl>"
        "<p class='live' aria-live='polite' id='job-live'></p>"
        + table("Runs", [("Run", ""), ("Area", ""), ("Seed", ""), ("Status", ""),
                         ("Progress", "")], rows, table_id="runs-table")
        + "</div>")
    return page(f"Job {out.id}", body, scripts=("sort.js", "job.js"), current="/jobs")
