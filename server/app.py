"""The FastAPI application of the API: `/api/v1` routes, `/healthz`, OpenAPI docs at `/docs`.

At start-up it applies the Alembic migrations, registers the built-in planners and areas, and
starts the periodic sweep (`server.sweeper`). The service as `flybo serve` runs it, with the web
pages, the sandboxed dry run of uploaded planners and the current benchmark version, is composed
in `flybo.app`.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import gc
import logging
import threading
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager

import anyio.to_thread
from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from sqlalchemy import Engine, func, select
from sqlalchemy.orm import Session, sessionmaker
from starlette.exceptions import HTTPException as StarletteHTTPException

from server.area_sync import sync_areas as sync_builtin_areas
from server.catalog import sync_builtin_planners
from server.db import make_engine, make_session_factory, read_only, session_scope
from server.middleware import install_middleware
from server.migrate import upgrade
from server.models import PlannerRow, Run, RunState
from server.planner_package import CheckSlots, PlannerCheck
from server.routes import areas, curves, groups, health, jobs, leaderboard, planners, runs
from server.settings import Settings, load_settings
from server.shared_state import EpochNet, read_results_epoch
from server.sweeper import sweep

log = logging.getLogger(__name__)
API_PREFIX = "/api/v1"
THREADS = 400
MAX_CONCURRENT_REQUESTS = 300  # `flybo serve` passes it to uvicorn; beyond it, 503


def create_app(settings: Settings | None = None, *, sweeper: bool = True,
               sync_areas: bool = True, planner_check: PlannerCheck | None = None,
               benchmark_version: str | Callable[[], str] | None = None) -> FastAPI:
    """The API; `sweeper` and `sync_areas` turn off the background work (for tests).

    `planner_check` dry-runs an uploaded planner that passed the static checks; without one,
    planner uploads are refused (503). `benchmark_version` is the current benchmark version
    (the leaderboard's default), or a function computing it at start-up; without one, the
    newest result's version is taken as current (`server.benchmark_versions`)."""
    settings = settings or load_settings()
    engine = make_engine(settings.db_url)
    sessions = make_session_factory(engine)
    read_sessions = make_session_factory(read_only(engine))
    lifespan = _lifespan(settings, engine, sessions, benchmark_version=benchmark_version,
                         sweeper=sweeper, sync_areas=sync_areas)
    app = FastAPI(title="FLYBO", version="1", lifespan=lifespan,
                  description="Benchmark service for autonomous exploration planners.")
    app.state.settings = settings
    app.state.engine = engine
    app.state.sessions = sessions
    app.state.read_sessions = read_sessions
    app.state.job_reads = jobs.job_reader(read_only(engine))
    app.state.planner_check = planner_check
    app.state.check_slots = CheckSlots(settings.max_concurrent_checks)
    shared = settings.shared_redis_url
    app.state.results_epoch = functools.partial(read_results_epoch, shared) if shared else None
    app.state.benchmark_version = benchmark_version if isinstance(benchmark_version, str) \
        else None
    app.include_router(health.router)
    for router in (areas.router, planners.router, jobs.router, groups.router, runs.router,
                   leaderboard.router, curves.router):
        app.include_router(router, prefix=API_PREFIX)
    install_middleware(app, settings)
    _install_error_handlers(app)
    return app


Lifespan = Callable[[FastAPI], contextlib.AbstractAsyncContextManager[None]]


def _lifespan(settings: Settings, engine: Engine, sessions: sessionmaker[Session], *,
              benchmark_version: str | Callable[[], str] | None, sweeper: bool,
              sync_areas: bool) -> Lifespan:
    """Start-up (migrations, the built-in planners' rows, the current benchmark version, the
    background area sync and sweeper) and shutdown of one app."""

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        # A request holds its pooled connection until its response is validated, which for a
        # sync endpoint needs a worker thread again. With as many threads as connections, all
        # threads can end up waiting for a connection while every connection waits for a
        # thread. More threads than concurrent requests (uvicorn's limit, see `flybo serve`)
        # rule that out.
        anyio.to_thread.current_default_thread_limiter().total_tokens = THREADS
        await asyncio.to_thread(upgrade, engine)
        with session_scope(sessions) as session:
            await asyncio.to_thread(sync_builtin_planners, session)
        if callable(benchmark_version):
            try:
                app.state.benchmark_version = await asyncio.to_thread(benchmark_version)
            except Exception:
                log.exception("could not tell the current benchmark version; the newest "
                              "result's is taken as current")
        # What start-up built lives as long as the process: keep it out of the cyclic GC, whose
        # full passes over it stall every request under load. Once per process (a test process
        # starts many apps).
        if gc.get_freeze_count() == 0:
            gc.collect()
            gc.freeze()
        # Areas are built in a process of their own (`server.area_sync`), waited for by a
        # background thread: the API answers meanwhile, a job naming an area not synced yet
        # builds its row on demand, and shutdown does not wait for it.
        if sync_areas:
            threading.Thread(target=_sync_areas, args=(settings.db_url, sessions),
                             name="area-sync", daemon=True).start()
        sweeping = asyncio.create_task(_sweep_forever(sessions, settings)) if sweeper else None
        try:
            yield
        finally:
            if sweeping is not None:
                sweeping.cancel()
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await sweeping
            engine.dispose()

    return lifespan


def _sync_areas(db_url: str, sessions: sessionmaker[Session]) -> None:
    try:
        sync_builtin_areas(db_url, sessions)
    except Exception:
        log.exception("syncing the built-in areas failed")


async def _sweep_forever(sessions: sessionmaker[Session], settings: Settings) -> None:
    shared = settings.shared_redis_url
    net = EpochNet(shared) if shared else None
    while True:
        await asyncio.sleep(settings.sweep_interval_s)
        try:
            await asyncio.to_thread(sweep, sessions, settings)
            if net is not None:
                net.check(await asyncio.to_thread(_results_snapshot, sessions))
        except Exception:
            log.exception("sweep failed")


def _results_snapshot(sessions: sessionmaker[Session]) -> tuple[int, int, int]:
    """What the leaderboards are computed from, in brief: succeeded runs (count, highest id)
    and planners."""
    with sessions() as session:
        row = session.execute(select(
            func.count(Run.id), func.coalesce(func.max(Run.id), 0),
            select(func.count(PlannerRow.id)).scalar_subquery())
            .where(Run.status == RunState.SUCCEEDED.value)).one()
    return int(row[0]), int(row[1]), int(row[2] or 0)


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
