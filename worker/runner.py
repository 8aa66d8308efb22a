"""Running one stored run: claim it, fly it, store its results and artifacts, exactly once.

- **Claim** (`worker.claims`): a conditional UPDATE moves the run from `queued` (or `running`
  with a dead worker) to `running` with a fresh claim token. A duplicate message finds nothing
  to claim.
- **Heartbeat** (`worker.heartbeat`): a thread writes progress, the log tail and a heartbeat
  every few seconds, and reads cancellation. The simulation thread never waits on the database.
- **Finish**: artifacts are uploaded first, under keys unique to the attempt; then one
  transaction stores results, series and artifact rows (`worker.result_rows`) and sets the
  final state, only if the claim token still matches. So a run is `succeeded` only with
  everything stored, and an attempt that lost its claim (its worker was presumed dead) stores
  nothing.
- **Record** (`worker.run_record`): the result row names the benchmark version the run was made
  with, its whole reproducibility record (also in `result.json`) and every metric the measures
  reported. The record is built by `flybo.record.reproducibility_record`, which `flybo worker`
  installs (`install_record_builder`: this package may not import `flybo`); without it, or when
  it fails, the row keeps what the worker knows and says what is missing.
- **Speed** (`worker.speed`): the machine's speed factor (`sim.reference_speed`) is measured once
  per worker process, in the background as the process starts (`measure_speed_in_background`,
  called on Celery's `worker_process_init`), so no run pays for it.
- **Threads** (`worker.threads`): Open3D is limited to the worker's threads before the first ray.
- **Time limits**: Celery's soft time limit raised inside a planner's `plan` call is the
  platform's (`run_episode(platform_errors=...)`): the run fails as over its wall-time limit,
  not as a planner that raised.
"""

from __future__ import annotations

import logging
import tempfile
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from celery.exceptions import SoftTimeLimitExceeded
from sqlalchemy.orm import Session, sessionmaker

from server.models import FailureKind, RunState
from server.planner_package import read_stored_package
from server.settings import Settings
from server.shared_state import bump_results_epoch
from server.storage import ArtifactStore, ArtifactStoreError, StoredArtifact, settings_store
from worker.claims import Claim, claim, finish, save_tail, sessions_for, worker_name
from worker.heartbeat import LOG_TAIL_LINES, Heartbeat, RunAbortedError, RunLog
from worker.result_folder import RECORDING
from worker.result_rows import CONTENT_TYPES, result_rows, write_files
from worker.run_record import RecordBuilder, build_record, install_record_builder, record_version
from worker.run_spec import RunSpec, load_run_area, read_spec
from worker.sandbox.isolation import SandboxLimits
from worker.speed import machine_speed_factor, measure_speed_in_background
from worker.threads import limit_open3d, thread_report

if TYPE_CHECKING:
    from areas import Area
    from sim.interface import PlannerLike
    from sim.result import EpisodeResult

# What this module offered before its parts moved out: the same names, for their importers.
__all__ = ["CONTENT_TYPES", "LOG_TAIL_LINES", "Claim", "Heartbeat", "RecordBuilder",
           "RunAbortedError", "RunLog", "RunSpec", "build_record", "claim", "execute_run",
           "install_record_builder", "machine_speed_factor", "measure_speed_in_background",
           "record_version", "sessions_for", "worker_name"]

log = logging.getLogger(__name__)


def execute_run(run_id: int, settings: Settings) -> str:
    """Run `run_id` if it is there to be run; returns a word on what happened."""
    factory = sessions_for(settings)
    held = claim(factory, settings, run_id)
    if held is None:
        return "skipped"
    spec = read_spec(factory, run_id)
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
            save_tail(factory, held, run_log.tail_text())
            for logger in watched:
                logger.removeHandler(run_log)
            run_log.close()


@dataclass(frozen=True)
class _Flown:
    """A run flown, its files written and uploaded: what its final transaction stores."""

    area: Area
    result: EpisodeResult
    record: dict[str, Any]
    stored: dict[str, tuple[StoredArtifact, str]]


def _fly_and_store(factory: sessionmaker[Session], settings: Settings, held: Claim,
                   spec: RunSpec, tmp: Path, run_log: RunLog, beat: Heartbeat,
                   wall0: float) -> str:
    log.info("run %s attempt %s on %s: %s on %s, seed %s, preset %s, %.0f s", held.run_id,
             held.attempt, worker_name(), spec.planner, spec.area, spec.seed, spec.preset,
             spec.seconds)
    store = settings_store(settings)
    try:
        flown = _fly_and_upload(settings, store, held, spec, tmp, run_log, beat)
    except Exception as exc:
        return _failed(factory, settings, held, spec, wall0, exc)
    result = flown.result
    failed = result.status.value == "failed"
    done = finish(
        factory, held, RunState.FAILED if failed else RunState.SUCCEEDED, wall0,
        kind=FailureKind.PLANNER if failed else None,
        error=result.reason if failed else None,
        rows=lambda: result_rows(held.run_id, result, flown.area.plateau_s, flown.stored,
                                 flown.record),
    )
    if done and not failed and settings.shared_redis_url:
        bump_results_epoch(settings.shared_redis_url)  # the API processes' boards are stale
    return result.status.value if done else "lost its claim"


def _fly_and_upload(settings: Settings, store: ArtifactStore, held: Claim, spec: RunSpec,
                    tmp: Path, run_log: RunLog, beat: Heartbeat) -> _Flown:
    # First the speed factor: it waits for the measurement that the process started in a
    # thread, so the thread's first imports of the simulation stack (numba) never run
    # alongside this thread's own; two threads importing one stack at once can fail.
    speed = machine_speed_factor()
    limit_open3d()  # before the first ray: Open3D's oneTBB reads no environment variable
    log.info("run %s %s", held.run_id, thread_report())
    area = load_run_area(spec, store, settings.areas_dir)
    result = _simulate(spec, area, tmp, beat, store, settings, speed)
    log.info("run %s %s: %s; coverage %.4f, F-score %.4f", held.run_id, result.status.value,
             result.reason, result.coverage, result.surface.fscore)
    record = build_record(spec, area, result)
    log.info("run %s: benchmark version %s", held.run_id, record.get("benchmark_version"))
    files = write_files(result, tmp, record)
    keys = f"runs/{held.run_id}/attempt-{held.attempt}-{held.token[:8]}"
    run_log.flush()
    stored = {kind: (store.put(f"{keys}/{path.name}", path), ctype)
              for kind, (path, ctype) in {**files, "log": (run_log.path,
                                                       "text/plain; charset=utf-8")}.items()}
    return _Flown(area, result, record, stored)


def _failed(factory: sessionmaker[Session], settings: Settings, held: Claim, spec: RunSpec,
            wall0: float, exc: Exception) -> str:
    """The end of a run that raised: its final state, and a word on what happened."""
    from worker.sandbox.proxy import SandboxError  # the simulation stack, see load_run_area

    if isinstance(exc, RunAbortedError):
        if exc.why == "cancelled":
            finish(factory, held, RunState.CANCELLED, wall0, error="cancelled while running")
            return "cancelled"
        return "lost its claim"
    if isinstance(exc, SoftTimeLimitExceeded):
        soft = settings.run_soft_time_limit_s(spec.seconds)
        hard = settings.run_time_limit_s(spec.seconds)
        finish(factory, held, RunState.FAILED, wall0, kind=FailureKind.PLANNER,
               error=f"exceeded its wall-time limit: stopped after {soft:.0f} s "
                     f"(hard limit {hard:.0f} s)")
        return "timed out"
    if isinstance(exc, SandboxError):
        finish(factory, held, RunState.FAILED, wall0, kind=FailureKind.PLANNER, error=str(exc))
        return "failed"
    if isinstance(exc, ArtifactStoreError):
        finish(factory, held, RunState.FAILED, wall0, kind=FailureKind.PLATFORM,
               error=f"could not store the run's artifacts: {exc}")
        return "failed"
    log.error("run %s failed", held.run_id, exc_info=exc)
    finish(factory, held, RunState.FAILED, wall0, kind=FailureKind.PLATFORM,
           error=f"{type(exc).__name__}: {exc}{_raised_at(exc)}")
    return "failed"


def _raised_at(exc: BaseException) -> str:
    """' (at file:line in function)' of the innermost frame: a platform failure's error names
    where it was raised, so a rare one is traced from the run's row alone."""
    frames = traceback.extract_tb(exc.__traceback__)
    if not frames:
        return ""
    last = frames[-1]
    return f" (at {Path(last.filename).name}:{last.lineno} in {last.name})"


def _simulate(spec: RunSpec, area: Area, tmp: Path, beat: Heartbeat, store: ArtifactStore,
              settings: Settings, speed: float | None) -> EpisodeResult:
    from areas.build_lock import load_ground_truth_once  # the simulation stack, see load_run_area
    from planners.registry import make
    from sim.config import preset
    from sim.episode import run_episode

    truth = load_ground_truth_once(area)  # two workers starting on a new area compute it once
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

    def fly(planner: PlannerLike) -> EpisodeResult:
        # Celery's soft time limit, raised inside a `plan` call, is the platform's: it ends the
        # run through `_failed` instead of counting as the planner raising.
        return run_episode(area, truth, planner, preset(spec.preset), spec.seed,
                           planner_name=spec.planner, preset_name=spec.preset,
                           seconds=spec.seconds, recording_path=tmp / RECORDING,
                           progress=progress, speed_factor=speed,
                           platform_errors=(SoftTimeLimitExceeded,))

    if spec.planner_builtin and not settings.sandbox_builtin:
        return fly(make(spec.planner))
    return _fly_sandboxed(spec, tmp, store, settings, fly)


def _fly_sandboxed(spec: RunSpec, tmp: Path, store: ArtifactStore, settings: Settings,
                   fly: Callable[[PlannerLike], EpisodeResult]) -> EpisodeResult:
    """A built-in planner in the sandbox (`Settings.sandbox_builtin`), or an uploaded one."""
    from worker.sandbox.proxy import SandboxedPlanner  # the simulation stack, see load_run_area

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
