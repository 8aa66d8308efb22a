"""The whole service's web application, as `flybo serve` runs it: the API (`server.app`), the
web pages mounted on it (`web`), the sandboxed dry run of uploaded planners (`worker`), and the
benchmark version of this code (`flybo.versions`), the one the leaderboard shows by default.

`server` imports neither `web` nor `worker`; this entry point is where the three meet.
"""

from __future__ import annotations

from fastapi import FastAPI

from flybo.versions import benchmark_version as tree_version
from server.app import create_app as create_api
from server.settings import Settings
from web import install_web
from worker.sandbox.dry_run import dry_run
from worker.sandbox.isolation import probe_in_background


def create_app(settings: Settings | None = None, *, sweeper: bool = True,
               sync_areas: bool = True, benchmark_version: str | None = None) -> FastAPI:
    """The API with the website and planner uploads; the flags as in `server.app.create_app`.
    The current benchmark version is this tree's (computed at start-up) unless given."""
    app = create_api(settings, sweeper=sweeper, sync_areas=sync_areas, planner_check=dry_run,
                     benchmark_version=benchmark_version or tree_version)
    install_web(app)
    # The first upload then finds the sandbox probed, and stale planner cgroups swept.
    probe_in_background()
    return app
