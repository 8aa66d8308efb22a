"""Threads per worker process: computed from the workers and cores, set in each worker process
before its libraries load, overridden explicitly, and a user's own library variables win.

The process tests start workers the way `flybo serve --workers 2` does
(`flybo.worker_processes.start_workers`) and read the limits inside the started processes:
their environment, numba's configuration, Open3D's and OpenBLAS's own thread counts.
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path
from typing import Any

import pytest
from sqlalchemy import select

from flybo.worker_processes import start_workers, stop_workers, worker_environment
from server.db import make_engine, make_session_factory, session_scope
from server.jobs import create_job
from server.migrate import upgrade
from server.models import Run, User
from server.queue import enqueue_run
from server.schemas import JobCreate
from server.settings import load_settings
from worker.threads import (
    LIBRARY_VARIABLES,
    THREADS_ENV,
    ThreadSettingError,
    thread_environment,
    threads_per_worker,
    usable_cores,
)

# What a pool process of `flybo worker` does before a run: load the libraries, then limit
# Open3D (`worker.runner` calls `limit_open3d` before the first ray); then report.
PROBE = """
import json, os, sys
import numba, numpy, open3d
from worker.threads import LIBRARY_VARIABLES, blas_threads, limit_open3d
limit_open3d()
json.dump({"env": {name: os.environ.get(name) for name in LIBRARY_VARIABLES},
           "numba": numba.config.NUMBA_NUM_THREADS,
           "open3d": open3d.utility.get_max_threads(),
           "openblas": blas_threads()}, open(f"{sys.argv[1]}/probe-{os.getpid()}.json", "w"))
"""


def _probe(tmp_path: Path, count: int, threads: int | None = None) -> list[dict[str, Any]]:
    procs = start_workers(count, threads, command=[sys.executable, "-c", PROBE, str(tmp_path)])
    for proc in procs:
        assert proc.wait(timeout=120) == 0
    return [json.loads((tmp_path / f"probe-{proc.pid}.json").read_text()) for proc in procs]


def test_threads_are_the_cores_shared_out() -> None:
    assert threads_per_worker(2, cores=2, environ={}) == 1
    assert threads_per_worker(2, cores=8, environ={}) == 4
    assert threads_per_worker(3, cores=8, environ={}) == 2
    assert threads_per_worker(4, cores=2, environ={}) == 1  # never none
    assert threads_per_worker(1, cores=2, environ={}) == 2
    assert threads_per_worker(2, environ={}) == max(1, usable_cores() // 2)


def test_an_explicit_setting_overrides_the_default() -> None:
    assert threads_per_worker(2, 3, cores=2, environ={THREADS_ENV: "1"}) == 3
    assert threads_per_worker(2, cores=2, environ={THREADS_ENV: " 2 "}) == 2
    for bad in ("0", "two", "-1"):
        with pytest.raises(ThreadSettingError, match=THREADS_ENV):
            threads_per_worker(2, environ={THREADS_ENV: bad})
    with pytest.raises(ThreadSettingError, match="--threads-per-worker"):
        threads_per_worker(2, 0)


def test_a_users_own_library_variable_wins() -> None:
    env = thread_environment(1, {"OMP_NUM_THREADS": "3", "MKL_NUM_THREADS": "", "PATH": "/bin"})
    assert env["OMP_NUM_THREADS"] == "3"
    assert env["MKL_NUM_THREADS"] == env["OPENBLAS_NUM_THREADS"] == env["NUMBA_NUM_THREADS"] == "1"
    assert env[THREADS_ENV] == "1" and env["PATH"] == "/bin"
    assert worker_environment(2, 2, {"NUMBA_NUM_THREADS": "1"})["NUMBA_NUM_THREADS"] == "1"


@pytest.mark.slow
def test_serve_with_two_workers_limits_each_process(tmp_path: Path,
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    for name in (*LIBRARY_VARIABLES, THREADS_ENV):
        monkeypatch.delenv(name, raising=False)
    expected = max(1, usable_cores() // 2)
    for report in _probe(tmp_path, 2):
        assert report["env"] == dict.fromkeys(LIBRARY_VARIABLES, str(expected))
        assert report["numba"] == expected
        assert report["open3d"] == expected
        assert report["openblas"] in (expected, None)  # None: numpy without a bundled OpenBLAS


@pytest.mark.slow
def test_the_explicit_setting_and_a_users_omp_reach_the_process(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    for name in (*LIBRARY_VARIABLES, THREADS_ENV):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    (report,) = _probe(tmp_path, 1, threads=2)
    assert report["env"]["OMP_NUM_THREADS"] == "1"
    assert report["open3d"] == 1  # Open3D follows OMP_NUM_THREADS, the user's here
    assert report["numba"] == 2 and report["env"]["OPENBLAS_NUM_THREADS"] == "2"


@pytest.mark.slow
def test_a_run_in_a_started_worker_flies_with_the_limits(tmp_path: Path,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """`flybo worker` as `flybo serve --workers 2` starts it: its pool process logs the limits
    it flew the run with."""
    for name in list(os.environ):
        if (name.startswith("FLYBO_") and name != "FLYBO_CACHE_DIR") or name in LIBRARY_VARIABLES:
            monkeypatch.delenv(name)
    monkeypatch.setenv("FLYBO_DATA_DIR", str(tmp_path / "data"))
    settings = load_settings()
    engine = make_engine(settings.db_url)
    upgrade(engine)
    factory = make_session_factory(engine)
    from server.catalog import sync_builtin_planners

    with session_scope(factory) as session:
        sync_builtin_planners(session)
        user = User(name="alice")
        session.add(user)
        session.flush()
        created = create_job(session, settings, user,
                             JobCreate(planner="classic", areas=["maze"], runs=1, seconds=3))
    ((run_id, seconds),) = created.runs
    enqueue_run(settings, run_id, seconds)
    workers = start_workers(2)
    try:
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline:
            with factory() as session:
                run = session.scalars(select(Run).where(Run.id == run_id)).one()
                if run.status in ("succeeded", "failed", "cancelled"):
                    break
            time.sleep(1.0)
    finally:
        stop_workers(workers)
    assert run.status == "succeeded", run.error
    expected = max(1, usable_cores() // 2)
    line = next(line for line in (run.log_tail or "").splitlines() if "threads:" in line)
    for name in LIBRARY_VARIABLES:
        assert f"{name} {expected}" in line
    assert f"Open3D {expected}" in line and f"numba {expected}" in line
