"""What a browser sees: leaderboard pages, plots and the 3D replay.

The pages read through the server's layer (`server.*`); `install_web` mounts them on the API's
app (`flybo.app` does, for `flybo serve`).
"""

from __future__ import annotations

from pathlib import Path

from fastapi import FastAPI
from fastapi.staticfiles import StaticFiles

from web import areas_page, jobs_page, leaderboard_page, planners_page, run_page
from web.replay import routes as replay_routes

STATIC = Path(__file__).resolve().parent / "static"


def install_web(app: FastAPI) -> None:
    """Mount the website's routes and static files on the service's app."""
    for module in (leaderboard_page, areas_page, planners_page, jobs_page, run_page,
                   replay_routes):
        app.include_router(module.router)
    app.mount("/static", StaticFiles(directory=STATIC), name="static")
