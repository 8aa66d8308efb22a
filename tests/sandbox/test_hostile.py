"""Hostile planners in the sandbox: each is contained, with the right reason, and this process
(the worker) and everything outside the planner's folder stay untouched."""

from __future__ import annotations

import os
import textwrap
import threading
import time
from pathlib import Path

import pytest

from server.planner_package import load_package
from sim.config import preset
from sim.episode import run_episode
from sim.result import RunStatus
from worker.sandbox.dry_run import dry_run, tiny_area
from worker.sandbox.isolation import SandboxLimits
from worker.sandbox.proxy import SandboxedPlanner, SandboxError

HEADER = """
import os, sys, socket, ctypes
import numpy as np
from planners.api import Plan, Planner
"""


def _planner(body: str, *, reset: str = "") -> str:
    return HEADER + textwrap.dedent(f"""
class Hostile(Planner):
    def reset(self, ctx):
        super().reset(ctx)
{textwrap.indent(textwrap.dedent(reset) or "pass", " " * 8)}

    def plan(self, obs):
{textwrap.indent(textwrap.dedent(body), " " * 8)}
""")


# No start-up turn: the first plan is asked for at once.
CONFIG = preset("exact").model_copy(update={"startup_spin": False})


def _fly(tmp_path: Path, source: str, seconds: float = 4.0, **limits: float) -> str:
    """Fly the planner in `source`; returns the reason the run ended."""
    code = tmp_path / "code"
    code.mkdir(parents=True)
    (code / "planner.py").write_text(source)
    area, truth = tiny_area()
    settings = SandboxLimits(**{"plan_timeout_s": 4.0, "memory_mib": 512,
                                "file_size_mib": 8, **limits})
    with SandboxedPlanner(code=code, limits=settings) as planner:
        try:
            result = run_episode(area, truth, planner, CONFIG, 0, seconds=seconds)
        except SandboxError as exc:
            return str(exc)
    assert result.status is RunStatus.FAILED, result.reason
    return result.reason


@pytest.fixture
def canary(tmp_path: Path) -> Path:
    path = tmp_path / "outside" / "canary.txt"
    path.parent.mkdir()
    path.write_text("untouched")
    return path


CASES = {
    "opens a socket": (
        "socket.create_connection(('127.0.0.1', 5432), timeout=1)\nreturn Plan.finished()",
        "network access is not allowed"),
    "forks": ("os.fork()\nreturn Plan.finished()", "starting processes is not allowed"),
    "starts a shell": ("os.system('touch /tmp/flybo-shell-was-here')\nreturn Plan.finished()",
                       "starting processes is not allowed"),
    "loops forever": ("while True:\n    pass", "took longer than 4 s"),
    "reads /etc/passwd": ("open('/etc/passwd').read()\nreturn Plan.finished()",
                          "No such file or directory: '/etc/passwd'"),
    "returns NaN": ("return Plan(np.full((1, 4), np.nan))", "not finite"),
    "returns the wrong type": ("return {'waypoints': [[0, 0, 0, 0]]}", "must return a Plan"),
    "raises in reset": ("return Plan.finished()", "reset raised RuntimeError: boom"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_contained(case: str, tmp_path: Path, canary: Path, isolated: None) -> None:
    body, expected = CASES[case]
    reset = "raise RuntimeError('boom')" if case == "raises in reset" else ""
    reason = _fly(tmp_path, _planner(body, reset=reset))
    assert expected in reason
    assert canary.read_text() == "untouched"
    assert not Path("/tmp/flybo-shell-was-here").exists()


def test_fork_bomb_through_native_code_is_capped(tmp_path: Path, isolated: None) -> None:
    # ctypes calls fork() directly, past the audit hook: the pids cgroup caps it, the plan's
    # time limit ends it, and killing the process group and the cgroup removes every child.
    body = ("libc = ctypes.CDLL(None)\nwhile True:\n    libc.fork()")
    reason = _fly(tmp_path, _planner(body), processes=16)
    assert "took longer than 4 s" in reason or "process" in reason
    assert os.getpid() > 0  # and we are still here to say so


def test_memory_hog_is_killed(tmp_path: Path, isolated: None) -> None:
    body = "hog = []\nwhile True:\n    hog.append(bytearray(64 * 1024 * 1024))"
    reason = _fly(tmp_path, _planner(body), memory_mib=512)
    assert "memory limit of 512 MiB" in reason


def test_flood_of_output_is_cut(tmp_path: Path, isolated: None) -> None:
    body = "while True:\n    print('x' * 1_000_000, flush=True)"
    reason = _fly(tmp_path, _planner(body), file_size_mib=8)
    assert "file size limit" in reason


def test_writes_outside_its_folder_are_refused(tmp_path: Path, canary: Path,
                                               isolated: None) -> None:
    body = f"open({str(canary)!r}, 'w').write('owned')\nreturn Plan.finished()"
    reason = _fly(tmp_path, _planner(body))
    assert "writing outside the working folder" in reason or "No such file" in reason
    assert canary.read_text() == "untouched"
    # Even past the audit hook, the file is not in the planner's view of the filesystem.
    native = (f"fd = ctypes.CDLL(None).open({str(canary).encode()!r}, 1)\n"
              "raise RuntimeError(f'open gave {fd}')")
    reason = _fly(tmp_path / "native", _planner(native))
    assert "open gave -1" in reason
    assert canary.read_text() == "untouched"


def test_secrets_and_ground_truth_are_out_of_sight(tmp_path: Path, isolated: None,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("FLYBO_SECRET_KEY", "canary-secret")
    from areas.cache import cache_dir

    truth_dir = str(cache_dir())
    assert Path(truth_dir).exists()
    body = (f"seen = {{'env': sorted(os.environ), 'truth': os.path.exists({truth_dir!r}),"
            " 'root': sorted(os.listdir('/root'))}\nraise RuntimeError(repr(seen))")
    reason = _fly(tmp_path, _planner(body))
    assert "canary-secret" not in reason and "FLYBO_SECRET_KEY" not in reason
    # /root holds only the Python installation the planner runs on.
    assert "'truth': False" in reason and "'root': ['.pyenv']" in reason


def test_out_of_bounds_plans_fail_the_run(tmp_path: Path, isolated: None) -> None:
    body = "return Plan(np.array([[1e6, 0.0, 1.0, 0.0]]))"
    reason = _fly(tmp_path, _planner(body), seconds=20.0)
    assert "consecutive plans were invalid" in reason


def test_the_worker_runs_the_next_planner_afterwards(tmp_path: Path, isolated: None) -> None:
    _fly(tmp_path / "a", _planner("while True:\n    pass"))
    good = _planner("return Plan(np.array([[*obs.pose.position, obs.pose.yaw + 1.0]]))")
    code = tmp_path / "good"
    code.mkdir()
    (code / "planner.py").write_text(good)
    area, truth = tiny_area()
    with SandboxedPlanner(code=code) as planner:
        result = run_episode(area, truth, planner, CONFIG, 0, seconds=4.0)
    assert result.status is RunStatus.SUCCEEDED and result.iterations > 0


def test_the_area_cannot_be_rebuilt(tmp_path: Path, isolated: None) -> None:
    # With the area's name and the `areas` package, `areas.registry.load_area(ctx.area)` would
    # rebuild the exact scene; the planner process has neither.
    body = """
found = {'area': self.ctx.area}
try:
    import areas.registry
    found['areas'] = areas.registry.__file__
except ImportError as exc:
    found['areas'] = type(exc).__name__
found['on_path'] = sorted(p for p in sys.path if os.path.isdir(os.path.join(p, 'areas'))
                          and os.listdir(os.path.join(p, 'areas')))
raise RuntimeError(repr(found))
"""
    reason = _fly(tmp_path, _planner(body))
    assert "'area': 'hidden'" in reason and "maze" not in reason and "check-room" not in reason
    assert "'areas': 'ModuleNotFoundError'" in reason and "'on_path': []" in reason


def test_the_context_sent_hides_the_area_only() -> None:
    from dataclasses import replace

    import numpy as np

    from sim.camera import CameraConfig
    from sim.geometry import Pose
    from sim.interface import PlannerContext
    from sim.vehicle import VehicleLimits
    from worker.sandbox.protocol import HIDDEN_AREA, decode_context, encode_context, hide_area

    ctx = PlannerContext("maze", np.zeros(3), np.ones(3), Pose(np.zeros(3), 0.0),
                         VehicleLimits(), 0.4, CameraConfig(), np.random.default_rng(3),
                         indoor=False)
    sent = decode_context(encode_context(hide_area(ctx)))
    assert sent.area == HIDDEN_AREA and "maze" not in repr(encode_context(hide_area(ctx)))
    assert sent.rng.random() == replace(ctx, rng=np.random.default_rng(3)).rng.random()
    assert sent.safety_radius_m == ctx.safety_radius_m and sent.limits == ctx.limits
    assert sent.indoor is False  # the area's class is told, its name is not


# Reopens its input pipe for writing (through libc: the audit hook is no boundary), fills it,
# and points the planner process's reader at a pipe nobody writes to: it never reads again.
STOPS_READING = """
if not hasattr(self, 'kept'):
    fd_in = int(sys.argv[sys.argv.index('--fd-in') + 1])
    libc = ctypes.CDLL(None, use_errno=True)
    writer = libc.open(f'/proc/self/fd/{fd_in}'.encode(), os.O_WRONLY | os.O_NONBLOCK)
    if writer < 0:
        raise OSError(ctypes.get_errno(), 'cannot reopen the input pipe')
    for chunk in (b'x' * 4096, b'x'):
        try:
            while True:
                os.write(writer, chunk)
        except BlockingIOError:
            pass
    idle = os.pipe()
    self.kept = (os.dup(fd_in), writer, *idle)
    os.dup2(idle[0], fd_in)
return Plan(np.array([[*obs.pose.position, obs.pose.yaw + 0.5]]))
"""


def test_a_planner_that_fills_its_input_and_stops_reading_fails_its_call(
        tmp_path: Path, isolated: None) -> None:
    outcome: dict[str, str] = {}
    flight = threading.Thread(target=lambda: outcome.update(reason=_fly(
        tmp_path, _planner(STOPS_READING), seconds=30.0)), daemon=True)
    started = time.monotonic()
    flight.start()
    flight.join(timeout=120)
    assert not flight.is_alive(), "the runner hangs on the planner's full input pipe"
    assert "stopped reading its input" in outcome["reason"], outcome
    assert time.monotonic() - started < 60


def test_the_dry_run_has_a_wall_clock_limit(isolated: None) -> None:
    # Each part is within its own limit (the start, each call, the planning budget: 8 s
    # each), the whole is not: the dry run's clock ends it. The start-up spin takes most of the
    # dry run's simulated seconds, so the planner is asked only a few times: the start's 6 s
    # and two calls of 1.4 s already pass the 8 s.
    source = HEADER + textwrap.dedent("""
        import time
        time.sleep(6)

        class Slow(Planner):
            def plan(self, obs):
                time.sleep(1.4)
                # A small turn and no horizon: asked again as soon as it is flown.
                return Plan(np.array([[*obs.pose.position, obs.pose.yaw + 0.05]]),
                            horizon_s=0.0)
    """)
    tiny_area()  # built before the clock starts
    outcome = dry_run(load_package("planner.py", source.encode()), timeout_s=8.0)
    assert not outcome.passed
    assert "the dry run took longer than 8 s" in outcome.output, outcome.output
    assert outcome.wall_s < 10.0


def test_closing_removes_the_sandbox_s_cgroups(tmp_path: Path, isolated: None) -> None:
    # Killed processes keep a cgroup busy until they are reaped: closing waits for that
    # rather than leaving one cgroup behind per sandbox in a long-lived worker.
    code = tmp_path / "code"
    code.mkdir()
    (code / "planner.py").write_text(_planner("libc = ctypes.CDLL(None)\nwhile True:\n"
                                              "    libc.fork()"))
    area, truth = tiny_area()
    limits = SandboxLimits(plan_timeout_s=3.0, processes=16)
    with SandboxedPlanner(code=code, limits=limits) as planner:
        run_episode(area, truth, planner, CONFIG, 0, seconds=4.0)
        assert planner.cgroups is not None
        paths = list(planner.cgroups.paths)
    assert len(paths) == 2 and not any(path.exists() for path in paths)


# The fallback's hole, tried where the isolation is full: native calls past the audit hook read
# every process's environment it can see and /etc/shadow, and send what they found over UDP to
# a listener of the test's, on the host's loopback.
PAST_THE_HOOK = """
libc = ctypes.CDLL(None, use_errno=True)
found = {}
for pid in [p for p in os.listdir('/proc') if p.isdigit()]:
    try:
        found[pid] = open(f'/proc/{pid}/environ', 'rb').read().decode(errors='replace')
    except OSError as exc:
        found[pid] = type(exc).__name__
found['shadow'] = libc.open(b'/etc/shadow', 0)
payload = repr(found).encode()
fd = libc.socket(2, 2, 0)  # AF_INET, SOCK_DGRAM
address = bytes([2, 0]) + PORT.to_bytes(2, 'big') + bytes([127, 0, 0, 1]) + bytes(8)
sent = libc.sendto(fd, payload, len(payload), 0, address, 16)
found['sent'] = (sent, os.strerror(ctypes.get_errno()) if sent < 0 else None)
raise RuntimeError(repr(found))
"""


def test_native_code_past_the_audit_hook_finds_nothing_to_send(
        tmp_path: Path, isolated: None, monkeypatch: pytest.MonkeyPatch) -> None:
    import socket

    monkeypatch.setenv("FLYBO_SECRET_KEY", "canary-secret")
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as listener:
        listener.bind(("127.0.0.1", 0))
        listener.settimeout(0.5)
        port = listener.getsockname()[1]
        body = f"PORT = {port}\n{PAST_THE_HOOK}"
        reason = _fly(tmp_path, _planner(body))
        with pytest.raises(TimeoutError):
            listener.recvfrom(65536)  # nothing reached the host
    assert "canary-secret" not in reason and "FLYBO_" not in reason, reason
    assert "'shadow': -1" in reason, reason
    # Its own loopback only: there the datagram goes nowhere.
    assert "'sent': (" in reason, reason
