"""Running one stored run: claim it, fly it, store its results and artifacts, exactly once.

- **Claim**: a conditional UPDATE moves the run from `queued` (or `running` with a dead
  worker) to `running` with a fresh claim token. A duplicate message finds nothing to claim.
- **Heartbeat**: a thread writes progress, the log tail and a heartbeat every few seconds, and
  reads cancellation. The simulation thread never waits on the database.
- **Finish**: artifacts are uploaded first, under keys unique to the attempt; then one
  transaction stores results, series and artifact rows and sets the final state, only if the
  claim token still matches. So a run is `succeeded` only with everything stored, and an
  attempt that lost its claim (its worker was presumed dead) stores nothing.
- **Record**: the result row names the benchmark version the run was made with, its whole
  reproducibility record (also in `result.json`) and every metric the measures reported. The
  record is built by `flybo.record.reproducibility_record`, which `flybo worker` installs
  (`install_record_builder`: this package may not import `flybo`); without it, or when it
  fails, the row keeps what the worker knows and says what is missing.
- **Speed**: the machine's speed factor (`sim.reference_speed`) is measured once per worker
  process, in the background as the process starts (`measure_speed_in_background`, called on
  Celery's `worker_process_init`), so no run pays for it.
- **Time limits**: Celery's soft time limit raised inside a planner's `plan` call is the
  platform's (`run_episode(platform_errors=...)`): the run fails as over its wall-time limit,
  not as a planner that raised.
"""

from __future__ import annotations

import collections
import logging
import os
import secrets
import socket
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from datetime import timedelta
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
import numpy.typing as npt
from celery.exceptions import SoftTimeLimitExceeded
from sqlalchemy import Engine, or_, select, update
from sqlalchemy.orm import Session, sessionmaker

from server.db import make_engine, make_session_factory
from server.models import (
    UNKNOWN_VERSION,
    AreaRow,
    Artifact,
    Base,
    FailureKind,
    Job,
    MetricSeries,
    PlannerRow,
    Run,
    RunResult,
    RunState,
    utcnow,
)
from server.planner_package import read_stored_package
from server.settings import Settings
from server.storage import ArtifactStore, ArtifactStoreError, StoredArtifact, settings_store
from worker.result_folder import RECORDING, write_result_folder
from worker.sandbox.isolation import SandboxLimits
from worker.threads import limit_open3d, thread_report

if TYPE_CHECKING:
    from areas import Area
    from sim.config import EpisodeConfig
    from sim.interface import PlannerLike
    from sim.result import EpisodeResult

log = logging.getLogger(__name__)
LOG_TAIL_LINES = 60

_engines: dict[tuple[int, str], tuple[Engine, sessionmaker[Session]]] = {}


def sessions_for(settings: Settings) -> sessionmaker[Session]:
    """One engine per process and URL (created after a fork, never inherited)."""
    key = (os.getpid(), settings.db_url)
    if key not in _engines:
        engine = make_engine(settings.db_url)
        _engines[key] = (engine, make_session_factory(engine))
    return _engines[key][1]


def worker_name() -> str:
    return f"{socket.gethostname()}-{os.getpid()}"


# -- the machine's speed factor: measured once per process --------------------------------------

_speed_lock = threading.Lock()
_speed: list[float | None] = []  # empty until measured; [None] when measuring failed


def machine_speed_factor() -> float | None:
    """This machine's speed over the reference's (`sim.reference_speed.speed_factor`), measured
    on the first call of the process; a call meanwhile waits for it. None if it could not be
    measured (the episode then measures it itself, if its preset charges CPU time)."""
    with _speed_lock:
        if not _speed:
            try:
                from sim.reference_speed import speed_factor  # numba: in the run's process

                _speed.append(float(speed_factor()))
            except Exception as exc:
                log.warning("could not measure the machine's speed factor: %s", exc)
                _speed.append(None)
        return _speed[0]


def measure_speed_in_background() -> threading.Thread:
    """Start measuring the speed factor (about 2 s) in a thread of this process, so that a
    worker process is up at once and its first run finds the factor measured (or waits for
    the rest of the measurement)."""
    thread = threading.Thread(target=machine_speed_factor, name="speed-factor", daemon=True)
    thread.start()
    return thread


# -- the reproducibility record ------------------------------------------------------------------

class RecordBuilder(Protocol):
    """`flybo.record.reproducibility_record`'s signature."""

    def __call__(self, *, area: Area, planner_id: str, planner_config: dict[str, Any],
                 preset_name: str, preset: EpisodeConfig, seed: int,
                 speed_factor: float | None,
                 planner_fingerprint: str | None = None) -> dict[str, Any]: ...


_record_builder: list[RecordBuilder] = []


def install_record_builder(builder: RecordBuilder | None) -> None:
    """Build every run's record with `builder` from now on in this process (and in processes
    forked from it); None: without one (the stored record says it is missing)."""
    _record_builder.clear()
    if builder is not None:
        _record_builder.append(builder)


class RunAbortedError(Exception):
    """Raised from the progress callback to stop the simulation."""

    def __init__(self, why: str) -> None:
        super().__init__(why)
        self.why = why


@dataclass(frozen=True)
class Claim:
    run_id: int
    token: str
    attempt: int


def claim(factory: sessionmaker[Session], settings: Settings, run_id: int) -> Claim | None:
    """Take the run if nobody live holds it; None if it is final, held, or cancelled."""
    token = secrets.token_hex(16)
    now = utcnow()
    stale = now - timedelta(seconds=settings.heartbeat_timeout_s)
    with factory() as session:
        result = session.execute(
            update(Run).where(
                Run.id == run_id, Run.cancel_requested.is_(False),
                or_(Run.status == RunState.QUEUED.value,
                    (Run.status == RunState.RUNNING.value) & (Run.heartbeat_at < stale)))
            .values(status=RunState.RUNNING.value, claim_token=token,
                    attempts=Run.attempts + 1, worker=worker_name(), started_at=now,
                    heartbeat_at=now, progress=0.0, sim_time_s=0.0)
        )
        if not getattr(result, "rowcount", 0):
            # A queued run whose cancellation came first ends here.
            session.execute(update(Run).where(
                Run.id == run_id, Run.status == RunState.QUEUED.value,
                Run.cancel_requested.is_(True)).values(status=RunState.CANCELLED.value,
                                                       finished_at=now))
            session.commit()
            return None
        attempts = session.scalar(select(Run.attempts).where(Run.id == run_id)) or 1
        session.commit()
    return Claim(run_id, token, attempts)


class RunLog(logging.Handler):
    """The run's own log: every line to a file, the last ones kept for the live tail."""

    def __init__(self, path: Path) -> None:
        super().__init__(logging.INFO)
        self.path = path
        self.file = path.open("a", encoding="utf-8")
        self.tail: collections.deque[str] = collections.deque(maxlen=LOG_TAIL_LINES)
        self.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
        self.lock_tail = threading.Lock()

    def emit(self, record: logging.LogRecord) -> None:
        line = self.format(record)
        self.file.write(line + "\n")
        self.file.flush()
        with self.lock_tail:
            self.tail.append(line)

    def tail_text(self) -> str:
        with self.lock_tail:
            return "\n".join(self.tail)

    def close(self) -> None:
        self.file.close()
        super().close()


class Heartbeat(threading.Thread):
    """Writes progress and liveness; learns about cancellation and a lost claim."""

    def __init__(self, factory: sessionmaker[Session], settings: Settings, held: Claim,
                 run_log: RunLog, sim_seconds: float) -> None:
        super().__init__(name=f"heartbeat-{held.run_id}", daemon=True)
        self.factory, self.settings, self.held, self.run_log = factory, settings, held, run_log
        self.sim_seconds = sim_seconds
        self.sim_time = 0.0
        self.cancelled = threading.Event()
        self.lost = threading.Event()
        self.stop = threading.Event()

    def run(self) -> None:
        while not self.stop.wait(self.settings.heartbeat_interval_s):
            try:
                self.beat()
            except Exception as exc:  # the database is away: keep flying, try again
                log.warning("heartbeat of run %s failed: %s", self.held.run_id, exc)

    def beat(self) -> None:
        with self.factory() as session:
            result = session.execute(update(Run).where(
                Run.id == self.held.run_id, Run.claim_token == self.held.token,
                Run.status == RunState.RUNNING.value).values(
                heartbeat_at=utcnow(), sim_time_s=self.sim_time,
                progress=min(self.sim_time / max(self.sim_seconds, 1e-9), 0.999),
                log_tail=self.run_log.tail_text()))
            cancel = session.scalar(select(Run.cancel_requested).where(
                Run.id == self.held.run_id))
            session.commit()
        if not getattr(result, "rowcount", 0):
            self.lost.set()
        if cancel:
            self.cancelled.set()


@dataclass(frozen=True)
class _RunSpec:
    area: str
    area_file: str | None
    planner: str
    planner_builtin: bool
    planner_code: str | None  # artifact location of an uploaded planner's code
    planner_code_hash: str  # an uploaded planner's; "" for a built-in one
    planner_config: dict[str, Any]  # a built-in planner's default configuration
    preset: str
    seed: int
    seconds: float


def _spec(factory: sessionmaker[Session], run_id: int) -> _RunSpec:
    with factory() as session:
        run, area, planner = session.execute(
            select(Run, AreaRow, PlannerRow).join(AreaRow, Run.area_id == AreaRow.id)
            .join(Job, Run.job_id == Job.id).join(PlannerRow, Job.planner_id == PlannerRow.id)
            .where(Run.id == run_id)).one()
        defaults = planner.config.get("defaults") if planner.builtin else None
        return _RunSpec(area.name, area.stats.get("file"), planner.key, planner.builtin,
                        planner.config.get("code"), planner.code_hash or "",
                        dict(defaults or {}), run.preset, run.seed, run.seconds)


def _load_area(spec: _RunSpec, store: ArtifactStore, folder: Path) -> Area:
    """The area: a built-in (or locally imported) one by name, or an uploaded one from `folder`
    (`Settings.areas_dir`), fetched from the artifact store first if this machine lacks it."""
    # The simulation stack (Open3D, numba) loads in the process that flies a run, not in
    # Celery's parent process before it forks its pool.
    from areas.registry import load_area
    from areas.store import AreaStoreError, load_stored_area

    if spec.area_file is None:
        return load_area(spec.area)
    try:
        return load_stored_area(spec.area, folder)
    except AreaStoreError:
        pass  # not on this machine yet, or damaged: fetch it again
    source = store.open_path(spec.area_file)
    target = folder / f"{spec.area}.npz"
    folder.mkdir(parents=True, exist_ok=True)
    part = folder / f".{spec.area}.{os.getpid()}.part"
    part.write_bytes(source.read_bytes())
    os.replace(part, target)
    return load_stored_area(spec.area, folder)


def execute_run(run_id: int, settings: Settings) -> str:
    """Run `run_id` if it is there to be run; returns a word on what happened."""
    factory = sessions_for(settings)
    held = claim(factory, settings, run_id)
    if held is None:
        return "skipped"
    spec = _spec(factory, run_id)
    wall0 = time.monotonic()
    with tempfile.TemporaryDirectory(prefix=f"flybo-run-{run_id}-") as tmp_name:
        tmp = Path(tmp_name)
        run_log = RunLog(tmp / "run.log")
        watched = [logging.getLogger(n) for n in ("sim", "planners", "areas", "worker")]
        for logger in watched:
            logger.addHandler(run_log)
            logger.setLevel(logging.INFO)
        beat = Heartbeat(factory, settings, held, run_log, spec.seconds)
        beat.start()
        try:
            return _fly_and_store(factory, settings, held, spec, tmp, run_log, beat, wall0)
        finally:
            beat.stop.set()
            beat.join(timeout=10)
            _save_tail(factory, held, run_log.tail_text())
            for logger in watched:
                logger.removeHandler(run_log)
            run_log.close()


def _fly_and_store(factory: sessionmaker[Session], settings: Settings, held: Claim,
                   spec: _RunSpec, tmp: Path, run_log: RunLog, beat: Heartbeat,
                   wall0: float) -> str:
    from worker.sandbox.proxy import SandboxError  # the simulation stack, see _load_area

    store = settings_store(settings)
    log.info("run %s attempt %s on %s: %s on %s, seed %s, preset %s, %.0f s", held.run_id,
             held.attempt, worker_name(), spec.planner, spec.area, spec.seed, spec.preset,
             spec.seconds)
    try:
        limit_open3d()  # before the first ray: Open3D's oneTBB reads no environment variable
        log.info("run %s %s", held.run_id, thread_report())
        area = _load_area(spec, store, settings.areas_dir)
        result = _simulate(spec, area, tmp, beat, store, settings)
        outcome = result.status.value
        log.info("run %s %s: %s; coverage %.4f, F-score %.4f", held.run_id, outcome,
                 result.reason, result.coverage, result.surface.fscore)
        record = build_record(spec, area, result)
        log.info("run %s: benchmark version %s", held.run_id, record.get("benchmark_version"))
        files = _write_files(result, tmp, record)
        keys = f"runs/{held.run_id}/attempt-{held.attempt}-{held.token[:8]}"
        run_log.flush()
        stored = {kind: (store.put(f"{keys}/{path.name}", path), ctype)
                  for kind, (path, ctype) in {**files, "log": (run_log.path,
                                                           "text/plain; charset=utf-8")}.items()}
    except RunAbortedError as exc:
        if exc.why == "cancelled":
            _finish(factory, held, RunState.CANCELLED, wall0, error="cancelled while running")
            return "cancelled"
        return "lost its claim"
    except SoftTimeLimitExceeded:
        soft = settings.run_soft_time_limit_s(spec.seconds)
        hard = settings.run_time_limit_s(spec.seconds)
        _finish(factory, held, RunState.FAILED, wall0, kind=FailureKind.PLANNER,
                error=f"exceeded its wall-time limit: stopped after {soft:.0f} s "
                      f"(hard limit {hard:.0f} s)")
        return "timed out"
    except SandboxError as exc:
        _finish(factory, held, RunState.FAILED, wall0, kind=FailureKind.PLANNER, error=str(exc))
        return "failed"
    except ArtifactStoreError as exc:
        _finish(factory, held, RunState.FAILED, wall0, kind=FailureKind.PLATFORM,
                error=f"could not store the run's artifacts: {exc}")
        return "failed"
    except Exception as exc:
        log.exception("run %s failed", held.run_id)
        _finish(factory, held, RunState.FAILED, wall0, kind=FailureKind.PLATFORM,
                error=f"{type(exc).__name__}: {exc}")
        return "failed"
    failed = outcome == "failed"
    done = _finish(
        factory, held, RunState.FAILED if failed else RunState.SUCCEEDED, wall0,
        kind=FailureKind.PLANNER if failed else None,
        error=result.reason if failed else None,
        rows=lambda: _result_rows(held.run_id, result, area.plateau_s, stored, record),
    )
    return outcome if done else "lost its claim"


def _save_tail(factory: sessionmaker[Session], held: Claim, tail: str) -> None:
    """The last log lines, kept with the run whatever its end (only by the claim's holder)."""
    try:
        with factory() as session:
            session.execute(update(Run).where(Run.id == held.run_id,
                                              Run.claim_token == held.token).values(log_tail=tail))
            session.commit()
    except Exception as exc:  # the full log is in the artifact store when it could be stored
        log.warning("could not save the log tail of run %s: %s", held.run_id, exc)


def _simulate(spec: _RunSpec, area: Area, tmp: Path, beat: Heartbeat, store: ArtifactStore,
              settings: Settings) -> EpisodeResult:
    from areas import load_ground_truth  # the simulation stack, see _load_area
    from planners.registry import make
    from sim.config import preset
    from sim.episode import run_episode

    truth = load_ground_truth(area)
    last_note = [0.0]

    def progress(t: float, volume: float) -> None:
        beat.sim_time = t
        if beat.cancelled.is_set():
            raise RunAbortedError("cancelled")
        if beat.lost.is_set():
            raise RunAbortedError("lost")
        if t - last_note[0] >= 30.0:
            last_note[0] = t
            log.info("t = %.0f s, explored %.1f m³", t, volume)

    speed = machine_speed_factor()

    def fly(planner: PlannerLike) -> EpisodeResult:
        # Celery's soft time limit, raised inside a `plan` call, is the platform's: it ends the
        # run through `_fly_and_store`'s handler instead of counting as the planner raising.
        return run_episode(area, truth, planner, preset(spec.preset), spec.seed,
                           planner_name=spec.planner, preset_name=spec.preset,
                           seconds=spec.seconds, recording_path=tmp / RECORDING,
                           progress=progress, speed_factor=speed,
                           platform_errors=(SoftTimeLimitExceeded,))

    if spec.planner_builtin and not settings.sandbox_builtin:
        return fly(make(spec.planner))
    from worker.sandbox.proxy import SandboxedPlanner  # the simulation stack, see _load_area

    limits = SandboxLimits(plan_timeout_s=settings.sandbox_plan_timeout_s,
                           memory_mib=settings.sandbox_memory_mib,
                           run_planning_budget_s=settings.run_time_limit_s(spec.seconds))
    if spec.planner_builtin:
        with SandboxedPlanner(builtin=spec.planner, limits=limits) as sandboxed:
            return fly(sandboxed)
    if spec.planner_code is None:
        raise RuntimeError(f"planner {spec.planner} has no stored code")
    package = read_stored_package(store.open_path(spec.planner_code).read_bytes())
    code = package.extract(tmp / "code")
    with SandboxedPlanner(code=code, limits=limits) as sandboxed:
        try:
            return fly(sandboxed)
        finally:
            tail = sandboxed.stderr_tail().strip()
            if tail:  # the planner's own output: in the run log, for its owner only
                log.info("planner output (last lines):\n%s", tail)


CONTENT_TYPES = {"recording": "application/octet-stream", "mesh": "application/octet-stream",
                 "result": "application/json"}


def _write_files(result: EpisodeResult, tmp: Path,
                 record: dict[str, Any]) -> dict[str, tuple[Path, str]]:
    return {kind: (path, CONTENT_TYPES[kind])
            for kind, path in write_result_folder(result, tmp, record).items()}


def build_record(spec: _RunSpec, area: Area, result: EpisodeResult) -> dict[str, Any]:
    """The run's reproducibility record, by the installed builder; never raises. Without a
    builder, or when it fails, what the worker knows itself, with the gap in `missing`."""
    from sim.config import preset  # the simulation stack, see _load_area

    speed = result.charge.get("speed_factor")
    why = "no record builder is installed in this worker process (`flybo worker` installs it)"
    if _record_builder:
        try:
            return _record_builder[0](
                area=area, planner_id=spec.planner, planner_config=spec.planner_config,
                preset_name=spec.preset, preset=preset(spec.preset), seed=spec.seed,
                speed_factor=speed, planner_fingerprint=spec.planner_code_hash or None)
        except Exception as exc:
            log.exception("could not build the reproducibility record")
            why = f"record: {type(exc).__name__}: {exc}"
    return {
        "benchmark_version": None,
        "preset": {"name": spec.preset},
        "area": {"name": area.name, "sha256": area.content_hash},
        "planner": {"id": spec.planner, "code_sha256": spec.planner_code_hash or None},
        "seed": spec.seed,
        "machine": {"speed_factor": speed},
        "missing": [why],
    }


def record_version(record: dict[str, Any]) -> str:
    """The benchmark version a record names (`UNKNOWN_VERSION` when it names none)."""
    version = record.get("benchmark_version")
    return str(version)[:64] if isinstance(version, str) and version else UNKNOWN_VERSION


def _f32(values: npt.ArrayLike) -> bytes:
    return np.asarray(values, dtype="<f4").tobytes()


def _opt(value: float) -> float | None:
    return float(value) if np.isfinite(value) else None


def _plain_metrics(metrics: dict[str, Any]) -> dict[str, float | int | None]:
    """The measures' numbers as JSON keeps them: counts whole, others float, undefined None."""
    out: dict[str, float | int | None] = {}
    for key, value in metrics.items():
        if value is None or isinstance(value, bool):
            out[key] = None if value is None else int(value)
        elif isinstance(value, int | np.integer):
            out[key] = int(value)
        else:
            out[key] = _opt(float(value))
    return out


def _result_rows(run_id: int, result: EpisodeResult, plateau_s: float,
                 stored: dict[str, tuple[StoredArtifact, str]],
                 record: dict[str, Any]) -> list[Base]:
    from sim.metrics import timing_summary, volumetric_efficiency  # see _load_area

    times = np.asarray(result.volume_times)
    volume = np.asarray(result.volume_m3)
    at_plateau = volume[times <= plateau_s + 1e-6]
    timing = timing_summary(result.planning_times_ms)
    surface = result.surface
    rows: list[Base] = [
        RunResult(
            run_id=run_id, outcome=result.status.value, reason=result.reason,
            simulated_until_s=float(result.simulated_until),
            explored_volume_m3=float(result.explored_volume_m3),
            volume_at_plateau_m3=float(at_plateau[-1]) if len(at_plateau) else 0.0,
            observable_volume_m3=float(result.observable_volume_m3),
            coverage=float(result.coverage),
            volumetric_efficiency=float(volumetric_efficiency(result.explored_volume_m3,
                                                              result.sim_seconds)),
            precision=_opt(surface.precision), recall=_opt(surface.recall),
            fscore=_opt(surface.fscore), rmse_m=_opt(surface.rmse_m),
            collisions=int(result.collisions), path_length_m=float(result.path_length_m),
            iterations=int(result.iterations),
            planning_ms_median=_opt(timing.get("median", float("nan"))),
            planning_ms_mean=_opt(timing.get("mean", float("nan"))),
            planning_ms_max=_opt(timing.get("max", float("nan"))),
            wall_seconds=float(result.wall_seconds),
            benchmark_version=record_version(record), record=record,
            metrics=_plain_metrics(result.metrics)),
        MetricSeries(run_id=run_id, time_s=_f32(times), explored_volume_m3=_f32(volume),
                     recall_time_s=_f32(result.recall_times),
                     surface_recall=_f32(result.recall)),
    ]
    for kind, (artifact, ctype) in stored.items():
        rows.append(Artifact(run_id=run_id, kind=kind, location=artifact.location,
                             size_bytes=artifact.size_bytes, sha256=artifact.sha256,
                             content_type=ctype))
    return rows


def _finish(factory: sessionmaker[Session], held: Claim, state: RunState, wall0: float, *,
            kind: FailureKind | None = None, error: str | None = None,
            rows: Callable[[], list[Base]] | None = None) -> bool:
    """Set the final state (with the result rows) if this attempt still holds the run."""
    with factory() as session:
        changed = session.execute(update(Run).where(
            Run.id == held.run_id, Run.claim_token == held.token,
            Run.status == RunState.RUNNING.value).values(
            status=state.value, finished_at=utcnow(), progress=1.0, error=error,
            failure_kind=kind.value if kind else None,
            wall_time_s=time.monotonic() - wall0))
        if not getattr(changed, "rowcount", 0):
            session.rollback()
            return False
        if rows is not None:
            session.add_all(rows())
        session.commit()
    return True
