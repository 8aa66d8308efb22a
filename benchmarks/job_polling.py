"""Cost of polling `GET /api/v1/jobs/{id}`: the ORM answer it replaced against the Core-query
answer, and the 304 a client gets by sending the ETag back.

LOAD FIXTURE: one job of 20 runs (MAZE x 20 seeds, submitted through the API by an admin) with
mixed states: 5 succeeded, 5 running at various progress, 10 queued. The API is
`flybo.app.create_app` (no sweeper) behind a TestClient, on a SQLite file and then, when it
answers, a fresh PostgreSQL database. Beside the real route, the app gets the old one at
`/bench/orm-jobs/{id}`: the ORM load with `selectinload` of runs, areas, planner and owner, and
`server.jobs.job_out`, as `GET /jobs/{id}` answered before. Both bodies are checked to be
byte for byte equal. `GET /healthz` is timed beside them: the TestClient's and the
middleware's own cost, to subtract for what the route costs.

After a warm-up of 50 requests each, N sequential requests per path (default 500), in
alternating blocks of 50 so that other work on the machine weighs on every path alike; the
table gives mean, p50, p99 per request, the ratio of means to the ORM path, and the same ratio
above the /healthz floor.

Run: `.venv/bin/python benchmarks/job_polling.py [--requests 500] [--only sqlite]`.
PostgreSQL: `FLYBO_BENCH_POSTGRES_URL` (default `postgresql+psycopg://postgres@127.0.0.1:5432/test`,
used to create and drop the fresh database).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any

from fastapi import APIRouter
from fastapi.testclient import TestClient
from sqlalchemy import create_engine, text, update

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from common import print_table, write_json

from flybo.app import create_app
from server.db import make_engine, make_session_factory, session_scope
from server.deps import IdPath, SessionDep
from server.jobs import job_out
from server.migrate import upgrade
from server.models import Run
from server.routes.jobs import _load
from server.schemas import JobOut
from server.security import create_token
from server.settings import Settings

POSTGRES_ADMIN_URL = os.environ.get("FLYBO_BENCH_POSTGRES_URL",
                                    "postgresql+psycopg://postgres@127.0.0.1:5432/test")
RUNS = 20
BLOCK = 50
WARMUP = 50
ORM_PATH = "/bench/orm-jobs/{id}"
CORE_PATH = "/api/v1/jobs/{id}"

orm_router = APIRouter()


@orm_router.get("/bench/orm-jobs/{job_id}", response_model=JobOut)
def orm_get_job(job_id: IdPath, session: SessionDep) -> JobOut:
    """`GET /jobs/{id}` as it was answered before the Core query: ORM objects and `job_out`."""
    return job_out(_load(session, job_id))


def postgres_reachable() -> bool:
    try:
        engine = create_engine(POSTGRES_ADMIN_URL)
        with engine.connect() as conn:
            conn.execute(text("SELECT 1"))
        engine.dispose()
    except Exception:
        return False
    return True


@contextmanager
def service(tmp: Path, database_url: str) -> Iterator[tuple[TestClient, int]]:
    """The app with the old route beside the new one, and the id of the 20-run job."""
    settings = Settings(data_dir=tmp / "data", database_url=database_url)
    engine = make_engine(settings.db_url)
    upgrade(engine)
    sessions = make_session_factory(engine)
    with session_scope(sessions) as session:
        token = create_token(session, "bench", settings.secret_key, admin=True)
    app = create_app(settings, sweeper=False, sync_areas=False,
                     benchmark_version="job-polling-benchmark")
    app.include_router(orm_router)
    try:
        with TestClient(app) as client:
            created = client.post("/api/v1/jobs", headers={"Authorization": f"Bearer {token}"},
                                  json={"planner": "classic", "areas": ["maze"], "runs": RUNS,
                                        "seconds": 30})
            if created.status_code != 201:
                raise RuntimeError(f"could not submit the job: {created.text}")
            job = created.json()
            run_ids = [r["id"] for r in job["runs"]]
            with session_scope(sessions) as session:
                for i, run_id in enumerate(run_ids[:5]):
                    session.execute(update(Run).where(Run.id == run_id).values(
                        status="succeeded", progress=1.0 - i * 0.01))
                for i, run_id in enumerate(run_ids[5:10]):
                    session.execute(update(Run).where(Run.id == run_id).values(
                        status="running", progress=0.1 + 0.15 * i))
            yield client, int(job["id"])
    finally:
        engine.dispose()


def timed(client: TestClient, path: str, n: int, headers: dict[str, str],
          status: int) -> list[float]:
    """Seconds per request of `n` sequential GETs of `path`."""
    out: list[float] = []
    for _ in range(n):
        start = time.perf_counter()
        response = client.get(path, headers=headers)
        out.append(time.perf_counter() - start)
        if response.status_code != status:
            raise RuntimeError(f"GET {path}: {response.status_code}, wanted {status}")
    return out


def measure(client: TestClient, job_id: int, requests: int) -> list[dict[str, Any]]:
    orm, core = ORM_PATH.format(id=job_id), CORE_PATH.format(id=job_id)
    old, new = client.get(orm), client.get(core)
    if old.content != new.content:
        raise RuntimeError(f"the bodies differ:\n{old.text}\n{new.text}")
    etag = new.headers["etag"]
    # /healthz: what TestClient and the middleware cost by themselves, the floor of the rest.
    cases = {"ORM objects + job_out (before)": (orm, {}, 200),
             "Core query, 200 (now)": (core, {}, 200),
             "Core query, If-None-Match: 304 (now)": (core, {"If-None-Match": etag}, 304),
             "GET /healthz (floor)": ("/healthz", {}, 200)}
    for path, headers, status in cases.values():
        timed(client, path, WARMUP, headers, status)
    samples: dict[str, list[float]] = {name: [] for name in cases}
    done = 0
    while done < requests:
        block = min(BLOCK, requests - done)
        for name, (path, headers, status) in cases.items():
            samples[name] += timed(client, path, block, headers, status)
        done += block
    base = statistics.fmean(samples[next(iter(cases))])
    floor = statistics.fmean(samples["GET /healthz (floor)"])
    rows = []
    for name, values in samples.items():
        ms = sorted(1000.0 * v for v in values)
        mean = statistics.fmean(ms)
        rows.append({"path": name, "requests": len(ms), "bytes": len(old.content),
                     "mean_ms": mean, "p50_ms": ms[len(ms) // 2],
                     "p99_ms": ms[min(len(ms) - 1, int(0.99 * len(ms)))],
                     "speedup": 1000.0 * base / mean,
                     "speedup_above_floor": ((base - floor) / (mean / 1000.0 - floor)
                                             if mean / 1000.0 > floor else None)})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--requests", type=int, default=500, help="timed requests per path")
    parser.add_argument("--only", choices=("sqlite", "postgresql"), default=None)
    parser.add_argument("--label", default="job_polling",
                        help="name of the JSON file under benchmarks/results")
    args = parser.parse_args()
    from leaderboard_throughput import postgres_database

    results: dict[str, list[dict[str, Any]]] = {}
    for backend in ("sqlite", "postgresql"):
        if args.only not in (None, backend):
            continue
        if backend == "postgresql" and not postgres_reachable():
            print("PostgreSQL is not reachable: measured on SQLite only")
            continue
        with tempfile.TemporaryDirectory(prefix="flybo-bench-poll-") as tmp_name, \
                ExitStack() as stack:
            tmp = Path(tmp_name)
            url = (f"sqlite:///{tmp / 'flybo.sqlite'}" if backend == "sqlite"
                   else stack.enter_context(postgres_database()))
            with service(tmp, url) as (client, job_id):
                results[backend] = measure(client, job_id, args.requests)
    load = os.getloadavg()[0]
    print_table(
        f"GET /api/v1/jobs/{{id}}, one job of {RUNS} runs, {args.requests} sequential requests "
        f"per path through TestClient (blocks of {BLOCK}, alternating); load {load:.1f}",
        ["database", "path", "requests", "mean ms", "p50 ms", "p99 ms", "x faster",
         "x faster above floor"],
        [[backend, r["path"], r["requests"], f"{r['mean_ms']:.2f}", f"{r['p50_ms']:.2f}",
          f"{r['p99_ms']:.2f}", f"{r['speedup']:.2f}",
          "" if r["speedup_above_floor"] is None else f"{r['speedup_above_floor']:.2f}"]
         for backend, rows in results.items() for r in rows])
    path = write_json(args.label, {"runs_per_job": RUNS, "requests": args.requests,
                                   "block": BLOCK, "warmup": WARMUP, "loadavg_1min": load,
                                   "results": results})
    print(f"\nwrote {path}")


if __name__ == "__main__":
    main()
