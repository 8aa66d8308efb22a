"""The arguments of `flybo serve`, `worker`, `viewer`, `tokens`, of the HTTP client commands
`submit`, `jobs`, `results`, and of `benchmark` (a whole suite as one job group) and `report`
(the paper's tables and figures); the commands themselves are in `flybo.local_commands`,
`flybo.client_commands` and `flybo.suite_commands`.

Each command imports the stack it needs when it runs: the HTTP client commands never load the
service (FastAPI, SQLAlchemy, Celery), and no command loads the simulation (Open3D, numba)
unless it flies or checks a planner.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import Any

from flybo.baselines_commands import add_baselines_command, run_baselines
from flybo.client_commands import run_jobs, run_results, run_submit, run_submit_planner
from flybo.errors import CliError
from flybo.heldout_commands import add_heldout_command, run_heldout
from flybo.local_commands import run_serve, run_tokens, run_viewer, run_worker
from flybo.suite_commands import run_benchmark, run_report

COMMANDS = ("serve", "worker", "viewer", "tokens", "submit", "submit-planner", "jobs",
            "results", "benchmark", "report", "baselines", "heldout")
DEFAULT_SERVER = "http://127.0.0.1:8000"


def add_service_commands(sub: Any) -> None:
    _add_local_commands(sub)
    _add_client_commands(sub)
    add_baselines_command(sub)
    add_heldout_command(sub)


def _add_local_commands(sub: Any) -> None:
    serve = sub.add_parser("serve", help="the service on this machine: API, web pages and a "
                                         "worker, on SQLite and a local broker by default")
    serve.add_argument("--host", default="127.0.0.1")
    serve.add_argument("--port", type=int, default=8000)
    serve.add_argument("--workers", type=int, default=1,
                       help="worker processes to start beside the API (default 1; 0: none)")
    serve.add_argument("--api-workers", type=int, default=None, metavar="N",
                       help="API processes sharing the port (default FLYBO_API_WORKERS, else "
                            "one per usable core in production with Redis, else 1; more than "
                            "1 needs Redis, FLYBO_REDIS_URL or a redis:// broker)")
    serve.add_argument("--access-log", action="store_true",
                       help="log every request (off by default: under load the log line costs "
                            "more than a cached answer)")
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


def _add_client_commands(sub: Any) -> None:
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
    results.add_argument("--split", choices=("public", "heldout"), default="public",
                         help="the public areas' board (default) or the held-out areas'")
    results.add_argument("--heldout-generation", type=int, default=None,
                         help="with --split heldout: the generation (default: the current one)")
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
    bench.add_argument("--heldout", action="store_true",
                       help="also run the areas' held-out counterparts (the held-out board)")
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
    report.add_argument("--dataset", type=Path, default=None,
                        help="report this baseline dataset (.json.xz) alone, without a service")
    report.add_argument("--markdown", type=Path, default=None,
                        help="write the Markdown here (default OUT/report.md), its links "
                             "relative to it (docs/RESULTS.md: --out docs/results)")


def run_service_command(args: argparse.Namespace) -> None:
    {"serve": run_serve, "worker": run_worker, "tokens": run_tokens, "submit": run_submit,
     "jobs": run_jobs, "results": run_results, "submit-planner": run_submit_planner,
     "viewer": run_viewer, "benchmark": run_benchmark, "report": run_report,
     "baselines": run_baselines, "heldout": run_heldout}[args.command](args)


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

