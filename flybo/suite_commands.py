"""The suite's commands: `flybo benchmark` (planners x areas x runs as one job group, followed to
its end) and `flybo report` (the paper's tables and figures from a service, or from a baseline
dataset alone)."""

from __future__ import annotations

import argparse
import sys
import time
import uuid
from typing import Any

import httpx
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from flybo.client_commands import request
from flybo.errors import CliError


def _names(values: list[str]) -> list[str]:
    """Names given space- or comma-separated."""
    return [n.strip() for v in values for n in v.split(",") if n.strip()]


def run_benchmark(args: argparse.Namespace) -> None:
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
    if getattr(args, "heldout", False):
        body["heldout"] = True
    # One key per invocation: a retry after a lost answer returns the same group.
    key = uuid.uuid4().hex
    group = request(args, "POST", "/groups", auth=True, json=body,
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
                group = request(args, "GET", f"/groups/{group_id}")
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


def run_report(args: argparse.Namespace) -> None:
    from flybo.report import ReportError, fetch_report_data, write_report  # the server's schemas

    try:
        if args.dataset is not None:
            from flybo.report_dataset import dataset_report_data  # SQLAlchemy, Alembic: on use

            if args.benchmark_version:
                raise CliError("--benchmark-version does not go with --dataset: a dataset "
                               "is of one benchmark version")
            data = dataset_report_data(args.dataset, args.preset)
        else:
            with httpx.Client(base_url=args.server.rstrip("/"), timeout=60.0) as client:
                data = fetch_report_data(client, args.preset, args.benchmark_version)
    except ReportError as exc:
        raise CliError(str(exc)) from None
    written = write_report(data, args.out, args.markdown)
    print(f"report of preset {args.preset}, benchmark version {data.benchmark_version} "
          f"({len(data.board.overall)} planner(s), "
          f"{len(data.board.areas)} area(s) with results) in {args.out}/:")
    for path in written:
        print(f"  {path}")
