"""`SandboxedPlanner`: a planner whose code runs in an isolated process.

The episode runner calls `reset` and `plan` as on any planner. Each call becomes one JSON
message on a pipe; the map goes through a shared memory file that the planner process can only
read. Every failure (crash, hang, limit, protocol breach, exception) raises `SandboxError` with a
reason for the run's record; the planner's stderr tail goes to the run log only.
"""

from __future__ import annotations

import contextlib
import logging
import os
import shutil
import signal
import subprocess
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from sim.interface import Observation, Plan, PlannerContext
from sim.map_view import MapView
from sim.occupancy import DirtyBoxSubscription, IndexBox
from worker.sandbox import cpu_usage, isolation, seccomp_filter
from worker.sandbox.bwrap_command import host_environment
from worker.sandbox.exit_reasons import exit_reason, stderr_tail
from worker.sandbox.isolation import SandboxLimits
from worker.sandbox.pipe import (
    ClosedError,
    ReadTimeoutError,
    StalledError,
    TooLargeError,
    read_line,
    write_all,
)
from worker.sandbox.protocol import (
    MAX_MESSAGE_BYTES,
    ProtocolError,
    box_message,
    clean_timing,
    decode_plan,
    encode_context,
    encode_message,
    encode_observation,
    hide_area,
    parse_message,
)

__all__ = ["SandboxError", "SandboxedPlanner"]

log = logging.getLogger(__name__)


class SandboxError(RuntimeError):
    """The sandboxed planner failed; the message is the reason recorded for the run."""


class SandboxedPlanner:
    """Runs `planner.py` from `code` (or built-in planner `builtin`) in a sandbox.

    Uploaded code needs full isolation: without it the constructor raises
    `isolation.SandboxUnavailableError` (not a `SandboxError`: the platform failed, not the
    planner), unless the operator allowed the insecure fallback. Built-in planners are the
    project's own code and run in whatever isolation there is.
    """

    def __init__(self, *, code: Path | None = None, builtin: str | None = None,
                 limits: SandboxLimits | None = None) -> None:
        if (code is None) == (builtin is None):
            raise ValueError("give exactly one of code and builtin")
        self.code, self.builtin = code, builtin
        self.limits = limits or SandboxLimits()
        self.iso = isolation.require_full() if code is not None else isolation.probe()
        self.proc: subprocess.Popen[bytes] | None = None
        self.tmp = Path(tempfile.mkdtemp(prefix="flybo-sbx-"))
        self.shm_dir = Path(tempfile.mkdtemp(prefix="flybo-map-", dir=_shm_root()))
        self.work = self.tmp / "work"
        self.work.mkdir()
        os.chmod(self.work, 0o777)  # the planner runs as an unprivileged user in its namespace
        self.stderr_path = self.tmp / "stderr.log"
        self.cgroups: isolation.Cgroups | None = None
        self.shared: np.memmap[Any, np.dtype[np.uint8]] | None = None
        self.subscription: DirtyBoxSubscription | None = None
        self.surface_subscription: DirtyBoxSubscription | None = None
        self.planning_s = 0.0
        self._cpu_seconds = 0.0
        # The CPU seconds of the planner process's reset (its map mirror and the planner's own
        # reset), which happens inside the first `plan` call, when the grid is known: an
        # in-process planner's reset is outside its `plan` calls.
        self.reset_cpu_seconds = 0.0
        # What the planner process reports of each call: map refresh and planner time, ms.
        self.timings: list[dict[str, float]] = []
        self._buffer = b""
        self._to: int | None = None  # the pipe to the planner process, non-blocking
        self._from: int | None = None
        # Why the process was ended by us (a stalled pipe, the dry run's clock), if it was.
        self._failure: str | None = None
        # Between plans, a thread sends the map's changes so that the planner process updates
        # its frontiers and clearance while the vehicle flies, as the runner's own trackers do,
        # instead of inside the timed `plan` call. The lock keeps each message whole and in
        # order with the map copy it describes; it is taken with the call's deadline, every
        # write under it has one, and reading the replies does not need it.
        self._send_lock = threading.Lock()
        self._stop_sync = threading.Event()
        self._sync_thread: threading.Thread | None = None

    # -- lifecycle -------------------------------------------------------------------------

    def __enter__(self) -> SandboxedPlanner:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self._stop_sync.set()
        # End the processes first: a map sync stuck on a full pipe then fails at once.
        self._kill_all()
        if self._sync_thread is not None:
            self._sync_thread.join(timeout=5)
        if self.proc is not None:
            self.proc.wait()
            for stream in (self.proc.stdin, self.proc.stdout):
                if stream is not None:
                    stream.close()
        # Under the send lock: a writer still running must not write into a reused fd number.
        if self._send_lock.acquire(timeout=5):
            try:
                for fd in (self._to, self._from):
                    if fd is not None:
                        with contextlib.suppress(OSError):
                            os.close(fd)
                self._to = self._from = None
            finally:
                self._send_lock.release()
        if self.cgroups is not None:
            self.cgroups.cleanup()
        self.shared = None
        shutil.rmtree(self.tmp, ignore_errors=True)
        shutil.rmtree(self.shm_dir, ignore_errors=True)

    def cpu_seconds(self) -> float:
        """CPU seconds of bubblewrap, the planner process and all it started, as the kernel
        counts them (`cpu_usage.cpu_seconds`): a `plan` call is charged the difference, never
        the planner's own report. Never decreases; 0 before the sandbox starts."""
        if self.proc is None or self.proc.returncode is not None:
            return self._cpu_seconds  # not started, or ended and reaped: its pid may be reused
        cgroups = self.cgroups.paths if self.cgroups is not None else []
        self._cpu_seconds = max(self._cpu_seconds, cpu_usage.cpu_seconds(self.proc.pid, cgroups))
        return self._cpu_seconds

    def stderr_tail(self) -> str:
        return stderr_tail(self.stderr_path)

    def _start(self) -> None:
        """Start the planner process and load the planner (not charged to planning time)."""
        if self._failure is not None:  # killed before it started
            raise SandboxError(self._failure)
        map_file = self.shm_dir / "map.u8"
        os.chmod(self.shm_dir, 0o755)  # the map file appears here at the first `plan`
        numba_seed = isolation.seed_numba_cache(self.tmp / "numba-seed")
        child_map, child_seed, child_code = isolation.child_paths(
            self.iso, numba_seed=numba_seed, code=self.code, map_file=map_file)
        to_child_r, to_child_w = os.pipe()
        from_child_r, from_child_w = os.pipe()
        source = ["--code", child_code] if child_code else ["--builtin", str(self.builtin)]
        seccomp_fd = seccomp_filter.filter_fd() if self.iso.seccomp else None
        args = isolation.command(
            self.iso, self.limits, numba_seed=numba_seed, code=self.code, map_dir=self.shm_dir,
            child_args=["--fd-in", str(to_child_r), "--fd-out", str(from_child_w),
                        "--map", child_map, "--numba-seed", child_seed, *source],
            seccomp_fd=seccomp_fd)
        passed = (to_child_r, from_child_w) + ((seccomp_fd,) if seccomp_fd is not None else ())
        self.cgroups = isolation.make_cgroups(self.iso, self.limits)
        with self.stderr_path.open("wb") as err:
            self.proc = subprocess.Popen(
                args, stdin=subprocess.DEVNULL, stdout=err, stderr=err,
                env=host_environment(self.work),
                cwd=self.work, pass_fds=passed, start_new_session=True,
                preexec_fn=isolation.preexec(self.limits, self.cgroups, self.iso))
        for fd in passed:
            os.close(fd)
        if self._failure is not None:
            self._kill()
        os.set_blocking(to_child_w, False)  # a planner that stops reading cannot block us
        self._to, self._from = to_child_w, from_child_r
        hello = self._receive(self.limits.start_timeout_s, "start")
        if not hello.get("ok"):
            raise SandboxError(str(hello.get("error", "the planner failed to load"))[:500])

    # -- the planner API -------------------------------------------------------------------

    def reset(self, ctx: PlannerContext) -> None:
        if self.proc is None:
            self._start()
        # The planner's own reset waits for the first observation, which gives the grid.
        self._ctx = ctx
        self._pending_reset = True

    def plan(self, obs: Observation) -> Plan:
        view = obs.map
        if self._pending_reset:
            shape = (int(view.shape[0]), int(view.shape[1]), int(view.shape[2]))
            map_file = self.shm_dir / "map.u8"
            # Three layers: the states, the surface weights and the surface directions.
            self.shared = np.memmap(map_file, dtype=np.uint8, mode="w+", shape=(3, *shape))
            os.chmod(map_file, 0o644)
            self.subscription = view.occupancy_map.subscribe()
            self.surface_subscription = view.surface_observations.subscribe()
            box: IndexBox | None = IndexBox.full(shape)
            surface_box: IndexBox | None = box
        else:
            box = surface_box = None  # taken with the send lock, in `_call`
        assert self.shared is not None
        if self._pending_reset:
            self.shared[0] = view.state
            self.shared[1] = view.surface_weight
            self.shared[2] = view.surface_directions
            before = self.cpu_seconds()
            self._call({"op": "reset", "ctx": encode_context(hide_area(self._ctx)),
                        "grid": {"shape": list(view.shape), "origin": view.origin.tolist(),
                                 "voxel_size": view.voxel_size}}, "reset")
            self.reset_cpu_seconds = self.cpu_seconds() - before
            self._pending_reset = False
            message = {"op": "plan", "obs": encode_observation(obs), "box": box_message(box),
                       "surface_box": box_message(surface_box)}
            reply = self._call(message, "plan")
            self._sync_thread = threading.Thread(target=self._sync_loop, args=(view,),
                                                 name="sandbox-map-sync", daemon=True)
            self._sync_thread.start()
        else:
            obs_message = encode_observation(obs)

            def with_changes() -> dict[str, Any]:
                changed, surface_changed = self._copy_changes(view)
                return {"op": "plan", "obs": obs_message, "box": box_message(changed),
                        "surface_box": box_message(surface_changed)}

            reply = self._call(with_changes, "plan")
        timing = reply.get("timing_ms")
        if isinstance(timing, dict):
            self.timings.append(clean_timing(timing))
        try:
            return decode_plan(reply.get("plan"))
        except ProtocolError as exc:
            raise SandboxError(f"the planner returned an invalid plan: {exc}") from None

    def _copy_changes(self, view: MapView) -> tuple[IndexBox | None, IndexBox | None]:
        """Copy the voxels changed since the last copy into shared memory (hold the send
        lock): the states' box and the surface layers' box."""
        box = self.subscription.take() if self.subscription is not None else None
        surface = (self.surface_subscription.take() if self.surface_subscription is not None
                   else None)
        if self.shared is not None:
            if box is not None:
                self.shared[0][box.slices()] = view.state[box.slices()]
            if surface is not None:
                region = surface.slices()
                self.shared[1][region] = view.surface_weight[region]
                self.shared[2][region] = view.surface_directions[region]
        return box, surface

    def _sync_loop(self, view: MapView, period_s: float = 0.2) -> None:
        while not self._stop_sync.wait(period_s):
            if not self._send_lock.acquire(timeout=period_s):
                continue  # a plan call is sending
            try:
                box, surface = self._copy_changes(view)
                if box is None and surface is None:
                    continue
                data = encode_message({"op": "sync", "box": box_message(box),
                                       "surface_box": box_message(surface)})
                self._write(data, time.monotonic() + self.limits.plan_timeout_s)
            except StalledError:
                self._stalled()
                return  # the next plan call reports it
            except (OSError, ValueError):
                return  # the process is gone; the next plan call reports why
            finally:
                self._send_lock.release()

    # -- the pipe ----------------------------------------------------------------------------

    def kill(self, reason: str) -> None:
        """End the planner process from any thread; the current or next call fails with
        `reason` (the dry run's wall-clock limit)."""
        self._failure = self._failure or reason
        self._kill_all()

    def _kill_all(self) -> None:
        """Kill the process group and whatever else is in the sandbox's cgroups."""
        self._kill()
        if self.cgroups is not None:
            for path in self.cgroups.paths:
                for pid in cpu_usage.cgroup_pids(path):
                    with contextlib.suppress(ProcessLookupError):
                        os.kill(pid, signal.SIGKILL)

    def _stalled(self) -> None:
        self.kill(f"the planner process stopped reading its input (the pipe to it stayed full "
                  f"for {self.limits.plan_timeout_s:g} s)")

    def _write(self, data: bytes, deadline: float) -> None:
        """Write all of `data` to the planner process before `deadline` (hold the send lock),
        else `StalledError`; `OSError` when the process is gone."""
        if self._to is None:
            raise BrokenPipeError("not started, or closed")
        write_all(self._to, data, deadline)

    def _call(self, message: dict[str, Any] | Callable[[], dict[str, Any]],
              what: str) -> dict[str, Any]:
        """Send `message` (or what it returns, built under the send lock) and wait for the
        reply, all within the call's time limit."""
        started = time.monotonic()
        budget = min(self.limits.plan_timeout_s,
                     self.limits.run_planning_budget_s - self.planning_s)
        if budget <= 0:
            self._kill()
            raise SandboxError(f"the planner used up its planning budget of "
                               f"{self.limits.run_planning_budget_s:g} s for the run")
        deadline = started + budget
        if not self._send_lock.acquire(timeout=budget):
            self._stalled()  # the map thread could not send in all that time
            raise SandboxError(self._death_reason(what))
        try:
            data = encode_message(message() if callable(message) else message)
            self._write(data, deadline)
        except StalledError:
            self._stalled()
            raise SandboxError(self._death_reason(what)) from None
        except (OSError, ValueError):
            raise SandboxError(self._death_reason(what)) from None
        finally:
            self._send_lock.release()
        reply = self._receive(deadline - time.monotonic(), what, limit=budget,
                              by_budget=budget < self.limits.plan_timeout_s)
        self.planning_s += time.monotonic() - started
        if not reply.get("ok"):
            raise SandboxError(f"the planner's {what} raised {reply.get('error', '?')}"[:1000])
        return reply

    def _receive(self, timeout: float, what: str, *, limit: float | None = None,
                 by_budget: bool = False) -> dict[str, Any]:
        """The next reply within `timeout` seconds (what is left of the call's `limit`, which
        is what was left of the run's planning budget when `by_budget`)."""
        limit = timeout if limit is None else limit
        if self._from is None:
            raise SandboxError(self._death_reason(what))
        try:
            line, self._buffer = read_line(self._from, self._buffer, time.monotonic() + timeout)
        except ReadTimeoutError:
            self._kill()
            if self._failure is not None:
                raise SandboxError(f"{self._failure} during {what}") from None
            if by_budget:
                raise SandboxError(f"the planner used up its planning budget of "
                                   f"{self.limits.run_planning_budget_s:g} s for the run") from None
            raise SandboxError(f"the planner's {what} took longer than {limit:g} s") from None
        except ClosedError:
            raise SandboxError(self._death_reason(what)) from None
        except TooLargeError:
            self._kill()
            raise SandboxError("the planner sent a message larger than "
                               f"{MAX_MESSAGE_BYTES} bytes") from None
        try:
            return parse_message(line)
        except ProtocolError as exc:
            self._kill()
            raise SandboxError(f"the planner broke the protocol: {exc}") from None

    def _kill(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait()

    def _death_reason(self, what: str) -> str:
        assert self.proc is not None
        try:
            code = self.proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            self._kill()
            code = self.proc.returncode
        if self._failure is not None:
            return f"{self._failure} during {what}"
        tail = self.stderr_tail().strip().splitlines()[-20:]
        if tail:
            log.warning("planner stderr (last lines):\n%s", "\n".join(tail))
        return exit_reason(code, what, stderr_path=self.stderr_path, limits=self.limits,
                           cgroups=self.cgroups, memory_cgroup=self.iso.cgroup_memory is not None)


def _shm_root() -> str | None:
    return "/dev/shm" if os.path.isdir("/dev/shm") and os.access("/dev/shm", os.W_OK) else None
