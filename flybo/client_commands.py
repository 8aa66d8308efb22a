"""The HTTP client commands `submit`, `submit-planner`, `jobs` and `results`, and the request
every client command sends through (`request`)."""

from __future__ import annotations

import argparse
import time
from typing import Any

import httpx
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

from flybo.errors import CliError


def request(args: argparse.Namespace, method: str, path: str, *, auth: bool = False,
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


def run_submit_planner(args: argparse.Namespace) -> None:
    try:
        data = args.file.read_bytes()
    except OSError as exc:
        raise CliError(f"cannot read {args.file}: {exc.strerror or exc}") from None
    planner = request(args, "POST", "/planners", auth=True,
                       files={"file": (args.file.name, data)},
                       data={"name": args.name, "description": args.description})
    print(f"planner {planner['id']} stored (code hash {planner['code_hash'][:12]})")


def run_submit(args: argparse.Namespace) -> None:
    body: dict[str, Any] = {"planner": args.planner, "runs": args.runs, "preset": args.preset,
                            "areas": [a.strip() for a in args.areas.split(",") if a.strip()]}
    if args.seconds is not None:
        body["seconds"] = args.seconds
    job = request(args, "POST", "/jobs", auth=True, json=body)
    print(f"job {job['id']}: {job['status']}, {len(job['runs'])} runs")
    if args.wait:
        _wait(args, job["id"])


def run_jobs(args: argparse.Namespace) -> None:
    if args.job_id is None:
        page = request(args, "GET", "/jobs", params={"limit": 50})
        for job in page["items"]:
            print(f"{job['id']:>6}  {job['status']:<10} {job['progress'] * 100:5.1f}%  "
                  f"{job['planner']:<16} {','.join(job['areas'])}  ({job['owner']})")
        return
    if args.wait:
        _wait(args, args.job_id)
        return
    job = request(args, "GET", f"/jobs/{args.job_id}")
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
            job = request(args, "GET", f"/jobs/{job_id}")
            bar.update(task, completed=job["progress"], description=job["status"])
            if job["status"] in final:
                break
            time.sleep(2.0)
    _print_job(job)
    if job["status"] != "succeeded":
        raise SystemExit(1)


def run_results(args: argparse.Namespace) -> None:
    params = {"preset": args.preset, **({"area": args.area} if args.area else {}),
              **({"benchmark_version": args.benchmark_version} if args.benchmark_version
                 else {})}
    split = getattr(args, "split", "public")
    generation = getattr(args, "heldout_generation", None)
    if generation is not None and split != "heldout":
        raise CliError("--heldout-generation goes with --split heldout")
    if split != "public":
        params["split"] = split
        if generation is not None:
            params["heldout_generation"] = generation
    board = request(args, "GET", "/leaderboard", params=params)
    held = (f", held-out generation {board.get('heldout_generation')}"
            if board.get("split") == "heldout" else "")
    print(f"preset {board['preset']}, benchmark version {board.get('benchmark_version')}{held}; "
          f"areas: {', '.join(board['areas']) or 'none yet'}")
    print(f"{'rank':>4}  {'planner':<18} {'areas':>5} {'coverage':>9} {'cov. rank':>9} "
          f"{'F-score':>8}")
    for p in board["overall"]:
        fscore = f"{p['mean_fscore']:.3f}" if p["mean_fscore"] is not None else "-"
        print(f"{p['rank']:>4}  {p['planner']:<18} {p['areas']:>5} {p['mean_coverage']:>9.4f} "
              f"{p['mean_coverage_rank']:>9.2f} {fscore:>8}")

