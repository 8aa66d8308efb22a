"""`flybo serve`, `worker`, `tokens` and the HTTP client commands `submit`, `jobs`, `results`,
`benchmark` (a whole suite as one job group) and `report` (the paper's tables and figures).

Each command imports the stack it needs when it runs: the HTTP client commands never load the
service (FastAPI, SQLAlchemy, Celery), and no command loads the simulation (Open3D, numba)
unless it flies or checks a planner.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import uuid
from pathlib import Path
from typing import TYPE_CHECKING, Any

import httpx
from pydantic import ValidationError
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
)

from flybo.errors import CliError

if TYPE_CHECKING:
    from sqlalchemy.orm import Session, sessionmaker

    from server.settings import Settings

COMMANDS = ("serve", "worker", "viewer", "tokens", "submit", "submit-planner", "jobs",
            "results", "benchmark", "report")
DEFAULT_SERVER = "http://127.0.0.1:8000"


def add_service_commands(sub: Any) -> None:
    serve = sub.add_parser("serve", help="the service on this machine: API, web pages and a "
                                         "worker, on SQLite and a local broker by default")
    serve.add_argument("--host", default="127.0.0.1")
    serve.add_argument("--port", type=int, default=8000)
    serve.add_argument("--workers", type=int, default=1,
                       help="worker processes to start beside the API (default 1; 0: none)")
    _threads_option(serve, "each worker process")
    serve.add_argument("--demo", action="store_true",
                       help="create a 'demo' user and submit a short MAZE + Classic job")
    serve.add_argument("--no-viewer", action="store_true",
                       help="do not start the 3D replay viewer (FLYBO_VIEWER_PORT)")
    viewer = sub.add_parser("viewer", help="the 3D replay viewer (viser) for stored runs or a "
                                           "recording file")
    viewer.add_argument("--host", default="127.0.0.1")
    viewer.add_argument("--port", type=int, default=None,
                        help="default FLYBO_VIEWER_PORT (8080)")
    viewer.add_argument("--recording", type=Path, default=None,
                        help="replay this recording file (no database needed)")
    viewer.add_argument("--compare", type=Path, default=None,
                        help="with --recording: a second recording on the same area")
    worker = sub.add_parser("worker", help="a Celery worker that runs queued runs")
    worker.add_argument("--concurrency", type=int, default=1,
                        help="runs at once in this worker (default 1)")
    _threads_option(worker, "each of its --concurrency pool processes")
    worker.add_argument("--loglevel", default="INFO")
    tokens = sub.add_parser("tokens", help="API tokens")
    tokens_sub = tokens.add_subparsers(dest="tokens_command", required=True)
    create = tokens_sub.add_parser("create", help="create a token (and the user if new)")
    create.add_argument("--user", required=True, help="user name")
    create.add_argument("--admin", action="store_true", help="the user may manage any job")

    def client(parser: argparse.ArgumentParser) -> None:
        parser.add_argument("--server", default=os.environ.get("FLYBO_SERVER", DEFAULT_SERVER),
                            help="service URL (env FLYBO_SERVER)")
        parser.add_argument("--token", default=os.environ.get("FLYBO_TOKEN"),
                            help="API token (env FLYBO_TOKEN)")

    submit = sub.add_parser("submit", help="submit a job to a service")
    client(submit)
    submit.add_argument("--planner", required=True)
    submit.add_argument("--areas", required=True, help="comma-separated area names")
    submit.add_argument("--runs", type=int, default=1, help="runs per area (default 1)")
    submit.add_argument("--seconds", type=float, default=None,
                        help="simulated seconds (default: each area's plateau time)")
    submit.add_argument("--preset", default="default")
    submit.add_argument("--wait", action="store_true", help="wait with a progress bar")
    upload = sub.add_parser("submit-planner", help="upload a planner (.py or .zip) to a service")
    client(upload)
    upload.add_argument("file", type=Path)
    upload.add_argument("--name", required=True)
    upload.add_argument("--description", default="")
    jobs = sub.add_parser("jobs", help="list jobs, or show one (and wait for it)")
    client(jobs)
    jobs.add_argument("job_id", nargs="?", type=int)
    jobs.add_argument("--wait", action="store_true", help="wait for the job to end")
    results = sub.add_parser("results", help="the leaderboard of a service")
    client(results)
    results.add_argument("--preset", default="default")
    results.add_argument("--area", default=None)
    results.add_argument("--benchmark-version", default=None,
                         help="the benchmark version whose results to rank (default: the "
                              "service's current one)")
    _add_suite_commands(sub, client)


def _threads_option(parser: argparse.ArgumentParser, who: str) -> None:
    parser.add_argument("--threads-per-worker", type=int, default=None, metavar="N",
                        help=f"threads of Open3D, numba and BLAS in {who} (default: the "
                             "usable cores shared out evenly, at least 1; env "
                             "FLYBO_WORKER_THREADS; OMP_NUM_THREADS and the other libraries' "
                             "own variables, when set, win)")


def _add_suite_commands(sub: Any, client: Any) -> None:
    bench = sub.add_parser("benchmark", help="submit the whole suite (planners x areas x runs) "
                                             "as one job group and wait for it")
    client(bench)
    bench.add_argument("--url", dest="server", help="same as --server")
    bench.add_argument("--planners", nargs="+", default=["all"],
                       help="planner names, or 'all' for every built-in planner (default)")
    bench.add_argument("--areas", nargs="+", default=["all"],
                       help="area names, or 'all' for every built-in area (default)")
    bench.add_argument("--runs", type=int, default=5, help="runs per area (default 5)")
    bench.add_argument("--preset", default="default")
    bench.add_argument("--name", default=None, help="a name for the group")
    length = bench.add_mutually_exclusive_group()
    length.add_argument("--seconds", type=float, default=None,
                        help="simulated seconds of every run (default: each area's plateau)")
    length.add_argument("--time-scale", type=float, default=None,
                        help="run each area for this fraction (0-1] of its plateau time")
    bench.add_argument("--follow", type=int, default=None, metavar="GROUP",
                       help="do not submit: wait for the group GROUP submitted earlier")
    bench.add_argument("--no-wait", action="store_true", help="submit and return")
    report = sub.add_parser("report", help="the paper's Tables 1-4 (CSV, Markdown) and "
                                           "Figures 4-6 (PNG, SVG) from a service")
    client(report)
    report.add_argument("--url", dest="server", help="same as --server")
    report.add_argument("--out", type=Path, default=Path("report"),
                        help="output folder (default ./report)")
    report.add_argument("--preset", default="default")
    report.add_argument("--benchmark-version", default=None,
                        help="the benchmark version whose results to report (default: the "
                             "service's current one; GET /api/v1/benchmark-versions lists them)")


def run_service_command(args: argparse.Namespace) -> None:
    {"serve": _serve, "worker": _worker, "tokens": _tokens, "submit": _submit, "jobs": _jobs,
     "results": _results, "submit-planner": _submit_planner,
     "viewer": _viewer, "benchmark": _benchmark, "report": _report}[args.command](args)


def check_planner(path: Path) -> None:
    """`flybo planners check FILE`: the upload's checks and dry run, on this machine."""
    # The sandbox and, for the dry run, the simulation: loaded by this command only.
    from server.planner_package import CheckUnavailableError, PackageError, load_package
    from worker.sandbox.dry_run import dry_run
    from worker.sandbox.isolation import probe

    try:
        data = path.read_bytes()
    except OSError as exc:
        raise CliError(f"cannot read {path}: {exc.strerror or exc}") from None
    try:
        package = load_package(path.name, data)
    except PackageError as exc:
        raise CliError(f"{path}: {exc}") from None
    for note in probe().notes:
        print(f"note: {note}")
    try:
        outcome = dry_run(package)
    except CheckUnavailableError as exc:
        raise CliError(f"{path}: the dry run needs the full sandbox: {exc} (for a local check "
                       "only, FLYBO_SANDBOX_ALLOW_INSECURE=1 runs it without)") from None
    print(outcome.output)
    if not outcome.passed:
        raise CliError(f"{path} failed its dry run")
    print(f"{path}: passed ({len(package.files)} files, code hash {package.code_hash[:12]}, "
          f"{outcome.wall_s:.1f} s)")


# -- local commands ---------------------------------------------------------------------------

def _settings() -> Settings:
    from server.settings import load_settings  # the service's code: only for its commands

    try:
        return load_settings()
    except ValidationError as exc:
        problems = "; ".join(str(e["msg"]) for e in exc.errors())
        raise CliError(f"invalid FLYBO_* settings: {problems}") from None


def _migrated(settings: Settings) -> sessionmaker[Session]:
    from server.db import make_engine, make_session_factory  # SQLAlchemy, Alembic: on use
    from server.migrate import upgrade

    engine = make_engine(settings.db_url)
    try:
        upgrade(engine)
    except Exception as exc:
        raise CliError(f"cannot reach or migrate the database {engine.url!r}: {exc}") from None
    return make_session_factory(engine)


def _tokens(args: argparse.Namespace) -> None:
    from server.db import session_scope  # SQLAlchemy: on use
    from server.security import create_token

    settings = _settings()
    name = args.user.strip()
    if not name or len(name) > 64:
        raise CliError("--user must be 1 to 64 characters")
    with session_scope(_migrated(settings)) as session:
        token = create_token(session, name, settings.secret_key, admin=args.admin)
    print(token)


def _worker(args: argparse.Namespace) -> None:
    if args.concurrency < 1:
        raise CliError("--concurrency must be at least 1")
    from worker.threads import ThreadSettingError, limit_this_process, threads_per_worker

    # First: the libraries read their thread limits as they load, in this process or in the
    # pool processes forked from it (`flybo serve` sets them in this one's environment).
    try:
        limit_this_process(threads_per_worker(args.concurrency, args.threads_per_worker))
    except ThreadSettingError as exc:
        raise CliError(str(exc)) from None
    _migrated(_settings())
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


def _viewer(args: argparse.Namespace) -> None:
    from web.replay.app import serve_viewer  # viser and the simulation: on use

    settings = _settings()
    if args.compare is not None and args.recording is None:
        raise CliError("--compare needs --recording")
    for path in (args.recording, args.compare):
        if path is not None and not path.is_file():
            raise CliError(f"no recording file {path}")
    if args.recording is None:
        _migrated(settings)
    try:
        serve_viewer(settings, args.host, args.port or settings.viewer_port,
                     recording=args.recording, compare=args.compare)
    except OSError as exc:
        raise CliError(f"cannot start the viewer: {exc}") from None


def _serve(args: argparse.Namespace) -> None:
    import uvicorn  # the whole service (API, pages, sandbox): only when serving

    from flybo.app import create_app
    from flybo.worker_processes import start_workers, stop_workers
    from server.app import MAX_CONCURRENT_REQUESTS
    from worker.threads import ThreadSettingError

    if not 0 < args.port < 65536:
        raise CliError(f"--port must be 1-65535, got {args.port}")
    settings = _settings()
    factory = _migrated(settings)
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
        print(f"FLYBO is serving at {url}/  (API docs: {url}/docs; {len(workers)} worker(s); "
              f"data in {settings.resolved_data_dir}"
              + (f"; 3D replay at {viewer.url}" if viewer is not None else "") + ")",
              flush=True)
        # Keep-alive longer than uvicorn's 5 s: under load a client may send on a connection
        # the server is just closing as idle, and see it reset.
        uvicorn.run(create_app(settings), host=args.host, port=args.port, log_level="info",
                    limit_concurrency=MAX_CONCURRENT_REQUESTS, timeout_keep_alive=30)
    finally:
        if viewer is not None:
            viewer.stop()
        stop_workers(workers)


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


# -- HTTP client ------------------------------------------------------------------------------

def _request(args: argparse.Namespace, method: str, path: str, *, auth: bool = False,
             headers: dict[str, str] | None = None, retries: int = 0, **kwargs: Any) -> Any:
    """`retries`: attempts after a transport error (only for requests safe to repeat, such as
    a POST with an Idempotency-Key)."""
    headers = dict(headers or {})
    if auth:
        if not args.token:
            raise CliError("an API token is needed: pass --token or set FLYBO_TOKEN "
                         "(`flybo tokens create --user NAME` on the server prints one)")
        headers["Authorization"] = f"Bearer {args.token}"
    for attempt in range(retries + 1):
        try:
            response = httpx.request(method, args.server.rstrip("/") + "/api/v1" + path,
                                     headers=headers, timeout=30.0, **kwargs)
            break
        except httpx.TransportError as exc:
            if attempt == retries:
                raise CliError(f"cannot reach {args.server}: {exc}") from None
            time.sleep(2.0)
        except httpx.HTTPError as exc:
            raise CliError(f"cannot reach {args.server}: {exc}") from None
    if response.status_code >= 400:
        try:
            detail = response.json().get("detail", response.text)
        except ValueError:
            detail = response.text
        raise CliError(f"{method} {path} answered {response.status_code}: {detail}")
    return response.json()


def _submit_planner(args: argparse.Namespace) -> None:
    try:
        data = args.file.read_bytes()
    except OSError as exc:
        raise CliError(f"cannot read {args.file}: {exc.strerror or exc}") from None
    planner = _request(args, "POST", "/planners", auth=True,
                       files={"file": (args.file.name, data)},
                       data={"name": args.name, "description": args.description})
    print(f"planner {planner['id']} stored (code hash {planner['code_hash'][:12]})")


def _submit(args: argparse.Namespace) -> None:
    body: dict[str, Any] = {"planner": args.planner, "runs": args.runs, "preset": args.preset,
                            "areas": [a.strip() for a in args.areas.split(",") if a.strip()]}
    if args.seconds is not None:
        body["seconds"] = args.seconds
    job = _request(args, "POST", "/jobs", auth=True, json=body)
    print(f"job {job['id']}: {job['status']}, {len(job['runs'])} runs")
    if args.wait:
        _wait(args, job["id"])


def _jobs(args: argparse.Namespace) -> None:
    if args.job_id is None:
        page = _request(args, "GET", "/jobs", params={"limit": 50})
        for job in page["items"]:
            print(f"{job['id']:>6}  {job['status']:<10} {job['progress'] * 100:5.1f}%  "
                  f"{job['planner']:<16} {','.join(job['areas'])}  ({job['owner']})")
        return
    if args.wait:
        _wait(args, args.job_id)
        return
    job = _request(args, "GET", f"/jobs/{args.job_id}")
    _print_job(job)


def _print_job(job: dict[str, Any]) -> None:
    print(f"job {job['id']}: {job['status']} ({job['progress'] * 100:.1f}%), {job['planner']}, "
          f"preset {job['preset']}")
    for run in job["runs"]:
        print(f"  run {run['id']:>6}  {run['area']:<14} seed {run['seed']:<3} {run['status']}")


def _wait(args: argparse.Namespace, job_id: int) -> None:
    final = {"succeeded", "failed", "cancelled"}
    with Progress(TextColumn(f"job {job_id}"), BarColumn(), TextColumn("{task.percentage:>5.1f}%"),
                  TextColumn("{task.description}"), TimeElapsedColumn()) as bar:
        task = bar.add_task("queued", total=1.0)
        while True:
            job = _request(args, "GET", f"/jobs/{job_id}")
            bar.update(task, completed=job["progress"], description=job["status"])
            if job["status"] in final:
                break
            time.sleep(2.0)
    _print_job(job)
    if job["status"] != "succeeded":
        raise SystemExit(1)


def _results(args: argparse.Namespace) -> None:
    params = {"preset": args.preset, **({"area": args.area} if args.area else {}),
              **({"benchmark_version": args.benchmark_version} if args.benchmark_version
                 else {})}
    board = _request(args, "GET", "/leaderboard", params=params)
    print(f"preset {board['preset']}, benchmark version {board.get('benchmark_version')}; "
          f"areas: {', '.join(board['areas']) or 'none yet'}")
    print(f"{'rank':>4}  {'planner':<18} {'areas':>5} {'coverage':>9} {'cov. rank':>9} "
          f"{'F-score':>8}")
    for p in board["overall"]:
        fscore = f"{p['mean_fscore']:.3f}" if p["mean_fscore"] is not None else "-"
        print(f"{p['rank']:>4}  {p['planner']:<18} {p['areas']:>5} {p['mean_coverage']:>9.4f} "
              f"{p['mean_coverage_rank']:>9.2f} {fscore:>8}")


# -- the suite: `flybo benchmark`, `flybo report` ---------------------------------------------

def _names(values: list[str]) -> list[str]:
    """Names given space- or comma-separated."""
    return [n.strip() for v in values for n in v.split(",") if n.strip()]


def _benchmark(args: argparse.Namespace) -> None:
    if args.follow is not None:
        _wait_group(args, args.follow)
        return
    if args.runs < 1:
        raise CliError("--runs must be at least 1")
    body: dict[str, Any] = {"planners": _names(args.planners), "areas": _names(args.areas),
                            "runs": args.runs, "preset": args.preset}
    for key in ("name", "seconds", "time_scale"):
        if getattr(args, key) is not None:
            body[key] = getattr(args, key)
    # One key per invocation: a retry after a lost answer returns the same group.
    key = uuid.uuid4().hex
    group = _request(args, "POST", "/groups", auth=True, json=body,
                     headers={"Idempotency-Key": key}, retries=2)
    print(f"group {group['id']} ({group['name']}): {len(group['planners'])} planner(s), "
          f"{len(group['areas'])} area(s), {group['runs']} runs, "
          f"{sum(p['simulated_s'] for p in group['planners']):,.0f} simulated s")
    if not args.no_wait:
        _wait_group(args, group["id"])


def _wait_group(args: argparse.Namespace, group_id: int) -> None:
    final = {"succeeded", "failed", "cancelled"}
    try:
        with Progress(TextColumn("{task.description:<20}"), BarColumn(), MofNCompleteColumn(),
                      TextColumn("{task.fields[states]}"), TimeElapsedColumn()) as bar:
            tasks: dict[str, Any] = {}
            while True:
                group = _request(args, "GET", f"/groups/{group_id}")
                rows = [("all runs", group["runs"], group["done"], group["by_status"])]
                rows += [(p["planner"], p["runs"], p["done"], p["by_status"])
                         for p in group["planners"]]
                for label, total, done, states in rows:
                    if label not in tasks:
                        tasks[label] = bar.add_task(label, total=total, states="")
                    bar.update(tasks[label], completed=done, states=_states(states))
                if group["status"] in final:
                    break
                time.sleep(2.0)
    except KeyboardInterrupt:
        print(f"\nstopped waiting; group {group_id} keeps running on the service. Follow it "
              f"with `flybo benchmark --follow {group_id}` (or GET /api/v1/groups/{group_id}); "
              f"stop it with POST /api/v1/groups/{group_id}/cancel.", file=sys.stderr)
        raise SystemExit(130) from None
    _print_group(group)
    if group["status"] != "succeeded":
        raise SystemExit(1)


def _states(counts: dict[str, int]) -> str:
    return ", ".join(f"{n} {s}" for s, n in counts.items() if n and s != "succeeded")


def _print_group(group: dict[str, Any]) -> None:
    print(f"group {group['id']} ({group['name']}): {group['status']}, preset "
          f"{group['preset']}, areas {', '.join(group['areas'])}")
    print(f"  {'planner':<18} {'runs':>5} {'ok':>5} {'failed':>6} {'cancelled':>9} "
          f"{'simulated s':>12}  jobs")
    for p in group["planners"]:
        s = p["by_status"]
        print(f"  {p['planner']:<18} {p['runs']:>5} {s['succeeded']:>5} {s['failed']:>6} "
              f"{s['cancelled']:>9} {p['simulated_s']:>12,.0f}  "
              f"{', '.join(str(j) for j in p['jobs'])}")
    print(f"results: `flybo results --preset {group['preset']}`; tables and figures: "
          f"`flybo report --preset {group['preset']}`")


def _report(args: argparse.Namespace) -> None:
    from flybo.report import ReportError, fetch_report_data, write_report  # the server's schemas

    try:
        with httpx.Client(base_url=args.server.rstrip("/"), timeout=60.0) as client:
            data = fetch_report_data(client, args.preset, args.benchmark_version)
    except ReportError as exc:
        raise CliError(str(exc)) from None
    written = write_report(data, args.out)
    print(f"report of preset {args.preset}, benchmark version {data.benchmark_version} "
          f"({len(data.board.overall)} planner(s), "
          f"{len(data.board.areas)} area(s) with results) in {args.out}/:")
    for path in written:
        print(f"  {path.name}")
