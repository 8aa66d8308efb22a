"""Server-rendered pages: the front page with the overall leaderboard and recent jobs.

Every value shown is escaped; the pages read through the same functions as the API.
"""

from __future__ import annotations

from html import escape

from fastapi import APIRouter
from fastapi.responses import HTMLResponse
from sqlalchemy import select
from sqlalchemy.orm import selectinload

from server.deps import SessionDep
from server.jobs import job_out
from server.leaderboard import build_leaderboard
from server.models import Job, Run

router = APIRouter(include_in_schema=False)

_STYLE = """
body{font-family:system-ui,sans-serif;margin:2rem auto;max-width:60rem;padding:0 1rem;
color:#111;background:#fff}table{border-collapse:collapse;width:100%;margin:1rem 0}
th,td{border-bottom:1px solid #ccc;padding:.35rem .5rem;text-align:left}
th{background:#f2f2f2}a{color:#0645ad}
"""


def _page(title: str, body: str) -> HTMLResponse:
    return HTMLResponse(
        f"<!doctype html><html lang='en'><head><meta charset='utf-8'>"
        f"<meta name='viewport' content='width=device-width, initial-scale=1'>"
        f"<title>{escape(title)}</title><style>{_STYLE}</style></head><body>{body}</body></html>",
        headers={"Content-Security-Policy": "default-src 'self'; style-src 'unsafe-inline'",
                 "X-Content-Type-Options": "nosniff"})


@router.get("/", response_class=HTMLResponse)
def index(session: SessionDep) -> HTMLResponse:
    board = build_leaderboard(session, "default")
    rows = "".join(
        f"<tr><td>{p.rank}</td><td>{escape(p.planner)}{' (baseline)' if p.builtin else ''}</td>"
        f"<td>{p.areas}</td><td>{p.mean_coverage:.3f}</td><td>{p.mean_coverage_rank:.2f}</td>"
        f"<td>{'-' if p.mean_fscore is None else f'{p.mean_fscore:.3f}'}</td></tr>"
        for p in board.overall) or "<tr><td colspan='6'>No results yet.</td></tr>"
    jobs = session.scalars(select(Job).order_by(Job.id.desc()).limit(20).options(
        selectinload(Job.runs).selectinload(Run.area), selectinload(Job.planner),
        selectinload(Job.user))).all()
    job_rows = "".join(
        f"<tr><td><a href='/api/v1/jobs/{j.id}'>{j.id}</a></td><td>{escape(o.planner)}</td>"
        f"<td>{escape(', '.join(o.areas))}</td><td>{escape(o.status)}</td>"
        f"<td>{o.progress * 100:.0f}%</td><td>{escape(o.owner)}</td></tr>"
        for j in jobs for o in [job_out(j)]) or "<tr><td colspan='6'>No jobs yet.</td></tr>"
    body = (
        "<h1>FLYBO leaderboard</h1>"
        "<p>Autonomous exploration planners on simulated areas, preset <code>default</code>. "
        "API documentation: <a href='/docs'>/docs</a>.</p>"
        "<table><caption>Overall, averaged over areas</caption><thead><tr><th scope='col'>Rank"
        "</th><th scope='col'>Planner</th><th scope='col'>Areas</th><th scope='col'>Coverage"
        "</th><th scope='col'>Coverage rank</th><th scope='col'>F-score</th></tr></thead>"
        f"<tbody>{rows}</tbody></table>"
        "<h2>Recent jobs</h2><table><thead><tr><th scope='col'>Job</th><th scope='col'>Planner"
        "</th><th scope='col'>Areas</th><th scope='col'>Status</th><th scope='col'>Progress"
        "</th><th scope='col'>Owner</th></tr></thead>"
        f"<tbody>{job_rows}</tbody></table>"
    )
    return _page("FLYBO leaderboard", body)
