"""The whole service's web application, as `flybo serve` runs it: the API (`server.app`), the
web pages mounted on it (`web`), and the sandboxed dry run of uploaded planners (`worker`).

`server` imports neither `web` nor `worker`; this entry point is where the three meet.
"""

from __future__ import annotations

from fastapi import FastAPI

from server.app import create_app as create_api
from server.settings import Settings
from web import install_web
from worker.sandbox.dry_run import dry_run


def create_app(settings: Settings | None = None, *, sweeper: bool = True,
               sync_areas: bool = True) -> FastAPI:
    """The API with the website and planner uploads; the flags as in `server.app.create_app`."""
    app = create_api(settings, sweeper=sweeper, sync_areas=sync_areas, planner_check=dry_run)
    install_web(app)
    return app
