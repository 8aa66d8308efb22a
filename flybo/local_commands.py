"""`flybo serve`, `worker`, `viewer` and `tokens`: the commands that run the service on this
machine. Each imports the service's stack (FastAPI, SQLAlchemy, Celery) when it runs."""

from __future__ import annotations

import argparse
import os
import sys
from typing import TYPE_CHECKING, Any

from pydantic import ValidationError

from flybo.errors import CliError

if TYPE_CHECKING:
    from sqlalchemy.orm import Session, sessionmaker

    from server.settings import Settings


def cli_settings() -> Settings:
    from server.settings import load_settings  # the service's code: only for its commands

    try:
        return load_settings()
    except ValidationError as exc:
        problems = "; ".join(str(e["msg"]) for e in exc.errors())
        raise CliError(f"invalid FLYBO_* settings: {problems}") from None


def migrated(settings: Settings) -> sessionmaker[Session]:
    from server.db import make_engine, make_session_factory  # SQLAlchemy, Alembic: on use
    from server.migrate import upgrade

    engine = make_engine(settings.db_url)
    try:
        upgrade(engine)
    except Exception as exc:
        raise CliError(f"cannot reach or migrate the database {engine.url!r}: {exc}") from None
    return make_session_factory(engine)


def run_tokens(args: argparse.Namespace) -> None:
    from server.db import session_scope  # SQLAlchemy: on use
    from server.security import ReservedUserError, create_token

    settings = cli_settings()
    name = args.user.strip()
    if not name or len(name) > 64:
        raise CliError("--user must be 1 to 64 characters")
    try:
        with session_scope(migrated(settings)) as session:
            token = create_token(session, name, settings.secret_key, admin=args.admin)
    except ReservedUserError as exc:
        raise CliError(f"--user: {exc}") from None
    print(token)


def run_worker(args: argparse.Namespace) -> None:
    if args.concurrency < 1:
        raise CliError("--concurrency must be at least 1")
    from worker.threads import ThreadSettingError, limit_this_process, threads_per_worker

    # First: the libraries read their thread limits as they load, in this process or in the
    # pool processes forked from it (`flybo serve` sets them in this one's environment).
    try:
        limit_this_process(threads_per_worker(args.concurrency, args.threads_per_worker))
    except ThreadSettingError as exc:
        raise CliError(str(exc)) from None
    migrated(cli_settings())
    from server.queue import QUEUE  # Celery; importing the worker's app configures it
    from worker.celery_app import app
    from worker.runner import install_record_builder

    # Every run's reproducibility record; the pool's processes inherit it when they fork.
    install_record_builder(_reproducibility_record)

    app.worker_main(["worker", f"--concurrency={args.concurrency}", "--pool=prefork",
                     "-Q", QUEUE, "-n", f"flybo-{os.getpid()}@%h", "--without-gossip",
                     "--without-mingle", f"--loglevel={args.loglevel}"])


def _reproducibility_record(**kwargs: Any) -> dict[str, Any]:
    """`flybo.record.reproducibility_record`, imported on the first run: it loads the simulation
    stack, which stays out of Celery's parent process."""
    from flybo.record import reproducibility_record

    return reproducibility_record(**kwargs)


def run_viewer(args: argparse.Namespace) -> None:
    from web.replay.app import serve_viewer  # viser and the simulation: on use

    settings = cli_settings()
    if args.compare is not None and args.recording is None:
        raise CliError("--compare needs --recording")
    for path in (args.recording, args.compare):
        if path is not None and not path.is_file():
            raise CliError(f"no recording file {path}")
    if args.recording is None:
        migrated(settings)
    try:
        serve_viewer(settings, args.host, args.port or settings.viewer_port,
                     recording=args.recording, compare=args.compare)
    except OSError as exc:
        raise CliError(f"cannot start the viewer: {exc}") from None


def run_serve(args: argparse.Namespace) -> None:
    import uvicorn  # the whole service (API, pages, sandbox): only when serving

    from flybo.app import create_app
    from flybo.baselines_load import load_shipped_baselines
    from flybo.worker_processes import start_workers, stop_workers
    from server.app import MAX_CONCURRENT_REQUESTS
    from worker.threads import ThreadSettingError

    if not 0 < args.port < 65536:
        raise CliError(f"--port must be 1-65535, got {args.port}")
    settings = cli_settings()
    api_workers = api_process_count(settings, args.api_workers)
    factory = migrated(settings)
    load_shipped_baselines(factory)
    try:
        workers = start_workers(args.workers, args.threads_per_worker)
    except ThreadSettingError as exc:
        raise CliError(str(exc)) from None
    url = f"http://{args.host}:{args.port}"
    viewer = None
    if not args.no_viewer:
        from web.replay.app import start_viewer  # viser: only when the viewer is wanted

        try:
            viewer = start_viewer(settings, args.host, settings.viewer_port)
        except OSError as exc:
            print(f"flybo: the 3D replay viewer did not start ({exc}); the site runs "
                  "without it", file=sys.stderr)
        # The viewer takes the next free port when its own is busy: link to where it is,
        # unless a public address was configured.
        if viewer is not None and "FLYBO_VIEWER_URL" not in os.environ:
            settings = settings.model_copy(update={"viewer_url": viewer.url})
    try:
        if args.demo:
            _demo(factory, settings, url)
        print(f"FLYBO is serving at {url}/  (API docs: {url}/docs; {api_workers} API "
              f"process(es), {len(workers)} worker(s); "
              f"data in {settings.resolved_data_dir}"
              + (f"; 3D replay at {viewer.url}" if viewer is not None else "") + ")",
              flush=True)
        # Keep-alive longer than uvicorn's 5 s: under load a client may send on a connection
        # the server is just closing as idle, and see it reset.
        options: dict[str, Any] = {"host": args.host, "port": args.port, "log_level": "info",
                                   "limit_concurrency": MAX_CONCURRENT_REQUESTS,
                                   "timeout_keep_alive": 30, "access_log": args.access_log}
        if api_workers == 1:
            uvicorn.run(create_app(settings), **options)
        else:
            # Each process builds the app from the same environment (the viewer's address
            # included); they share the listening socket, the kernel spreads connections.
            if viewer is not None and "FLYBO_VIEWER_URL" not in os.environ:
                os.environ["FLYBO_VIEWER_URL"] = viewer.url
            uvicorn.run("flybo.app:create_app", factory=True, workers=api_workers, **options)
    finally:
        if viewer is not None:
            viewer.stop()
        stop_workers(workers)


def api_process_count(settings: Settings, asked: int | None) -> int:
    """The API processes `flybo serve` runs: `asked`, else the settings' default for the usable
    cores. More than one needs Redis: rate limits kept per process would each allow the full
    rate, so N processes would let N times the limit through."""
    count = asked if asked is not None else settings.default_api_workers(
        len(os.sched_getaffinity(0)))
    if not 1 <= count <= 64:
        raise CliError(f"--api-workers must be 1-64, got {count}")
    if count > 1 and settings.shared_redis_url is None:
        raise CliError(f"--api-workers {count} needs Redis for the rate limits the API processes "
                       "share: set FLYBO_REDIS_URL (or a redis:// FLYBO_BROKER_URL), or serve "
                       "with --api-workers 1")
    return count


def _demo(factory: sessionmaker[Session], settings: Settings, url: str) -> None:
    from sqlalchemy import select  # the service stack: on use

    from server.catalog import sync_builtin_planners
    from server.db import session_scope
    from server.jobs import create_job
    from server.models import User
    from server.queue import enqueue_run
    from server.schemas import JobCreate
    from server.security import create_token

    with session_scope(factory) as session:
        sync_builtin_planners(session)
        token = create_token(session, "demo", settings.secret_key)
        user = session.scalars(select(User).where(User.name == "demo")).one()
        created = create_job(session, settings, user,
                             JobCreate(planner="classic", areas=["maze"], runs=2, seconds=60))
    for run_id, seconds in created.runs:
        enqueue_run(settings, run_id, seconds)
    print(f"demo user token: {token}\ndemo job: {url}/api/v1/jobs/{created.job.id}", flush=True)

