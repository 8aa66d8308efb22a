"""Fixtures of the replay tests: one real short run (MAZE + Classic, 20 s, preset exact) made
with `flybo run`, a service database holding it as runs, and a free port for each viewer."""

from __future__ import annotations

import hashlib
import socket
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from sqlalchemy.orm import Session, sessionmaker

from server.settings import Settings

SECONDS = 20.0


@pytest.fixture(scope="session")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder written by `flybo run`: recording.npz, mesh.ply, result.json."""
    from flybo.cli import main

    out = tmp_path_factory.mktemp("run") / "maze-classic"
    main(["run", "--area", "maze", "--planner", "classic", "--seconds", str(SECONDS),
          "--preset", "exact", "--seed", "1", "--out", str(out), "--quiet"])
    return out


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


@dataclass
class ServiceDb:
    settings: Settings
    sessions: sessionmaker[Session]
    with_recording: tuple[int, int]  # two runs with a recording (the first also has a mesh)
    without_recording: int  # a queued run


def _floats(values: list[float]) -> bytes:
    return np.asarray(values, dtype="<f4").tobytes()


@pytest.fixture(scope="session")
def service_db(tmp_path_factory: pytest.TempPathFactory, run_dir: Path) -> Iterator[ServiceDb]:
    """A migrated SQLite database and artifact folder holding the short run as runs 1 and 2."""
    from server.db import make_engine, make_session_factory, session_scope
    from server.migrate import upgrade
    from server.models import AreaRow, Artifact, Job, MetricSeries, PlannerRow, Run, User
    from server.storage import open_store

    settings = Settings(data_dir=tmp_path_factory.mktemp("service"))
    engine = make_engine(settings.db_url)
    upgrade(engine)
    sessions = make_session_factory(engine)
    store = open_store(settings.artifacts)
    with session_scope(sessions) as session:
        user = User(name="alice")
        planner = PlannerRow(name="classic", version=1)
        area = AreaRow(name="maze", content_hash="0" * 64, plateau_s=700.0, voxel_size=0.1)
        session.add_all([user, planner, area])
        session.flush()
        job = Job(user_id=user.id, planner_id=planner.id, preset="exact", seconds=SECONDS,
                  runs_per_area=3, request_hash="0" * 64)
        session.add(job)
        session.flush()
        runs = [Run(job_id=job.id, area_id=area.id, seed=seed, preset="exact", seconds=SECONDS,
                    status=status) for seed, status in ((1, "succeeded"), (2, "succeeded"),
                                                        (3, "queued"))]
        session.add_all(runs)
        session.flush()
        for run in runs[:2]:
            kinds = ["recording", "mesh"] if run is runs[0] else ["recording"]
            for kind in kinds:
                source = run_dir / ("recording.npz" if kind == "recording" else "mesh.ply")
                stored = store.put(f"runs/{run.id}/{source.name}", source)
                session.add(Artifact(run_id=run.id, kind=kind, location=stored.location,
                                     size_bytes=stored.size_bytes,
                                     sha256=hashlib.sha256(source.read_bytes()).hexdigest(),
                                     content_type="application/octet-stream"))
            # Run 1's curve: explored volume 10 m³ per second, recall 0.01 per second.
            times = [float(t) for t in range(int(SECONDS) + 1)]
            session.add(MetricSeries(run_id=run.id, time_s=_floats(times),
                                     explored_volume_m3=_floats([10.0 * t for t in times]),
                                     recall_time_s=_floats([10.0, 20.0]),
                                     surface_recall=_floats([0.1, 0.2])))
        ids = [r.id for r in runs]
    yield ServiceDb(settings, sessions, (ids[0], ids[1]), ids[2])
    engine.dispose()
