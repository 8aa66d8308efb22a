"""The FastAPI application: `/api/v1` routes, `/healthz`, OpenAPI docs at `/docs`.

At start-up it applies the Alembic migrations, registers the built-in planners and areas, and
starts the periodic sweep (`server.sweeper`).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException

from server.catalog import sync_builtin_areas, sync_builtin_planners
from server.db import make_engine, make_session_factory, session_scope
from server.middleware import install_middleware
from server.migrate import upgrade
from server.routes import areas, curves, health, jobs, leaderboard, planners, runs
from server.settings import Settings, load_settings
from server.sweeper import sweep

log = logging.getLogger(__name__)
API_PREFIX = "/api/v1"


def create_app(settings: Settings | None = None, *, sweeper: bool = True,
               sync_areas: bool = True) -> FastAPI:
    """The app; `sweeper` and `sync_areas` turn off the background work (for tests)."""
    settings = settings or load_settings()
    engine = make_engine(settings.db_url)
    sessions = make_session_factory(engine)

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        await asyncio.to_thread(upgrade, engine)
        with session_scope(sessions) as session:
            await asyncio.to_thread(sync_builtin_planners, session)
        # Areas are built in the background: the API answers meanwhile, and a job naming an
        # area not synced yet builds its row on demand.
        area_sync = asyncio.create_task(asyncio.to_thread(_sync_areas)) if sync_areas else None
        sweeping = asyncio.create_task(_sweep_forever()) if sweeper else None
        try:
            yield
        finally:
            for task in (sweeping, area_sync):
                if task is not None:
                    task.cancel()
                    with contextlib.suppress(asyncio.CancelledError, Exception):
                        await task
            engine.dispose()

    def _sync_areas() -> None:
        try:
            with session_scope(sessions) as session:
                sync_builtin_areas(session)
        except Exception:  # a concurrent insert by another process: it is synced either way
            log.exception("syncing the built-in areas failed")

    async def _sweep_forever() -> None:
        while True:
            await asyncio.sleep(settings.sweep_interval_s)
            try:
                await asyncio.to_thread(sweep, sessions, settings)
            except Exception:
                log.exception("sweep failed")

    app = FastAPI(title="FLYBO", version="1", lifespan=lifespan,
                  description="Benchmark service for autonomous exploration planners.")
    app.state.settings = settings
    app.state.engine = engine
    app.state.sessions = sessions
    app.include_router(health.router)
    for router in (areas.router, planners.router, jobs.router, runs.router,
                   leaderboard.router, curves.router):
        app.include_router(router, prefix=API_PREFIX)
    install_middleware(app, settings)
    from web import install_web  # the website reads through the server's layer

    install_web(app)
    _install_error_handlers(app)
    return app


def _install_error_handlers(app: FastAPI) -> None:
    @app.exception_handler(StarletteHTTPException)
    async def http_error(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        detail = exc.detail if isinstance(exc.detail, str) else str(exc.detail)
        return JSONResponse({"detail": detail}, exc.status_code, headers=exc.headers)

    @app.exception_handler(RequestValidationError)
    async def validation_error(request: Request, exc: RequestValidationError) -> JSONResponse:
        problems = []
        for err in exc.errors():
            where = ".".join(str(p) for p in err.get("loc", ()) if p != "body")
            problems.append(f"{where}: {err.get('msg', 'invalid')}" if where else
                            str(err.get("msg", "invalid")))
        return JSONResponse({"detail": "invalid request: " + "; ".join(problems),
                             "errors": [{"loc": list(e.get("loc", ())), "msg": e.get("msg")}
                                        for e in exc.errors()]}, 422)

    @app.exception_handler(Exception)
    async def internal_error(request: Request, exc: Exception) -> JSONResponse:
        log.exception("unhandled error on %s %s", request.method, request.url.path)
        return JSONResponse({"detail": "internal error; it has been logged"}, 500)
