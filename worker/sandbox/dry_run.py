"""The upload check's dry run: the planner flies a tiny room for a few simulated seconds.

The flight runs in a process of its own (`python -m worker.sandbox.dry_run`), one thread, with
the planner in the sandbox below it: the simulation's CPU and memory stay out of the process
that called `dry_run` (the API), which only waits for the verdict.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from functools import lru_cache
from pathlib import Path
from typing import Any

from server.planner_package import CheckOutcome, CheckUnavailableError, PlannerPackage
from worker.sandbox import isolation
from worker.sandbox.isolation import SandboxLimits
from worker.threads import thread_environment

DRY_RUN_SECONDS = 10.0
# The flight's process, beyond the dry run's own clock: starting Python and the simulation, and
# building the room.
PROCESS_GRACE_S = 60.0


@lru_cache(maxsize=1)
def tiny_area() -> tuple[Any, Any]:
    """A closed 6 x 5 x 3 m room and its ground truth, built once per process."""
    import trimesh

    from areas.ground_truth import compute_ground_truth
    from areas.importer import import_mesh

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "room.obj"
        trimesh.creation.box(extents=(6.0, 5.0, 3.0)).export(path)
        area = import_mesh(path, "check-room", plateau_s=60.0)
    return area, compute_ground_truth(area)


def fly(code: Path, timeout_s: float) -> CheckOutcome:
    """The dry run itself, in this process: the planner in folder `code`, in the sandbox, on
    `tiny_area` for `DRY_RUN_SECONDS`, within `timeout_s` of wall time.

    Raises `CheckUnavailableError` where the sandbox cannot contain uploaded code."""
    from sim.config import preset
    from sim.episode import run_episode
    from sim.result import RunStatus
    from worker.sandbox.proxy import SandboxedPlanner, SandboxError

    area, truth = tiny_area()
    started = time.monotonic()
    limits = SandboxLimits(start_timeout_s=timeout_s, plan_timeout_s=min(10.0, timeout_s),
                           run_planning_budget_s=timeout_s)
    try:
        planner = SandboxedPlanner(code=code, limits=limits)
    except isolation.SandboxUnavailableError as exc:
        raise CheckUnavailableError(str(exc)) from None
    # The per-call limits and the planning budget leave the time between calls and the
    # start open: the whole dry run gets a wall-clock limit of its own.
    clock = threading.Timer(timeout_s, planner.kill,
                            args=(f"the dry run took longer than {timeout_s:g} s",))
    clock.daemon = True
    with planner:
        clock.start()
        try:
            result = run_episode(area, truth, planner, preset("exact"), 0,
                                 planner_name="check", preset_name="exact",
                                 seconds=DRY_RUN_SECONDS)
        except SandboxError as exc:
            return CheckOutcome(False, f"{exc}\n{planner.stderr_tail()}".strip(),
                                time.monotonic() - started)
        finally:
            clock.cancel()
        output = planner.stderr_tail()
    wall = time.monotonic() - started
    if result.status is RunStatus.FAILED:
        return CheckOutcome(False, f"the dry run failed: {result.reason}\n{output}".strip(), wall)
    if wall > timeout_s:
        return CheckOutcome(False, f"the dry run took {wall:.0f} s, more than {timeout_s:g}", wall)
    return CheckOutcome(True, f"dry run of {DRY_RUN_SECONDS:g} s on a 6 x 5 x 3 m room: "
                              f"{result.iterations} plans, explored "
                              f"{result.explored_volume_m3:.1f} m³, {result.reason}\n{output}"
                        .strip(), wall)


def dry_run(package: PlannerPackage, *, timeout_s: float = 60.0) -> CheckOutcome:
    """Run the package's planner in the sandbox on `tiny_area` for `DRY_RUN_SECONDS`, in a
    process of its own (`fly` there).

    Raises `CheckUnavailableError` where the sandbox cannot contain uploaded code
    (`isolation.require_full`)."""
    try:
        isolation.require_full("the dry run of uploaded planners")
    except isolation.SandboxUnavailableError as exc:
        raise CheckUnavailableError(str(exc)) from None
    started = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="flybo-check-") as tmp:
        code = package.extract(Path(tmp) / "code")
        try:
            done = subprocess.run(
                [sys.executable, "-P", "-m", "worker.sandbox.dry_run", "--code", str(code),
                 "--timeout", repr(timeout_s)],
                env=thread_environment(1, os.environ), stdin=subprocess.DEVNULL,
                capture_output=True, text=True, timeout=timeout_s + PROCESS_GRACE_S)
        except subprocess.TimeoutExpired:
            return CheckOutcome(False, f"the dry run took longer than {timeout_s:g} s",
                                time.monotonic() - started)
    try:
        verdict = json.loads(done.stdout.strip().splitlines()[-1])
    except (IndexError, ValueError):
        # The flight's process itself failed: the platform's fault, not the planner's.
        raise CheckUnavailableError(
            f"the dry run's process ended with code {done.returncode}: "
            f"{done.stderr.strip()[-500:]}") from None
    if "unavailable" in verdict:
        raise CheckUnavailableError(str(verdict["unavailable"]))
    return CheckOutcome(bool(verdict["passed"]), str(verdict["output"]), float(verdict["wall_s"]))


def main(argv: list[str] | None = None) -> None:
    """`python -m worker.sandbox.dry_run --code DIR --timeout S`: `fly`, the verdict as one line
    of JSON on stdout."""
    parser = argparse.ArgumentParser(description=main.__doc__)
    parser.add_argument("--code", type=Path, required=True)
    parser.add_argument("--timeout", type=float, required=True)
    args = parser.parse_args(argv)
    try:
        outcome = fly(args.code, args.timeout)
    except CheckUnavailableError as exc:
        print(json.dumps({"unavailable": str(exc)}), flush=True)
        return
    print(json.dumps({"passed": outcome.passed, "output": outcome.output,
                      "wall_s": outcome.wall_s}), flush=True)


if __name__ == "__main__":
    main()
