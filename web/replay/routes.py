"""The website's link into the viewer: ``GET /runs/{run_id}/replay`` redirects to the viewer page
of that run, ``<viewer_url>/?run=<id>``.
"""

from __future__ import annotations

from fastapi import APIRouter, HTTPException
from fastapi.responses import RedirectResponse

from server.deps import SessionDep, SettingsDep
from server.settings import Settings
from web.replay.source import RunLookupError, find_stored_run

DEFAULT_VIEWER_URL = "http://127.0.0.1:8080"

router = APIRouter(include_in_schema=False)


def viewer_url(settings: Settings, run_id: int) -> str:
    """The viewer's page for one run; `settings.viewer_url` is the viewer's public address."""
    base = str(getattr(settings, "viewer_url", DEFAULT_VIEWER_URL)).rstrip("/")
    return f"{base}/?run={run_id}"


@router.get("/runs/{run_id}/replay")
def replay(run_id: int, session: SessionDep, settings: SettingsDep) -> RedirectResponse:
    try:
        find_stored_run(session, run_id)
    except RunLookupError as exc:
        raise HTTPException(404, str(exc)) from None
    return RedirectResponse(viewer_url(settings, run_id), status_code=307)
