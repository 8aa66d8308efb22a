"""Run inside the reproduced production container (`test_container_image`): the isolation probe,
then, where it finds full isolation, hostile planners in the sandbox and an honest one.

    python -m tests.sandbox.in_container [--probe-only]

Prints one line of JSON: the probe's result, whether uploaded code may run
(`isolation.require_full`), and the reason each planner's flight ended.
"""

from __future__ import annotations

import argparse
import json
import socket
import tempfile
from pathlib import Path

from sim.episode import run_episode
from sim.result import RunStatus
from tests.sandbox.test_hostile import CONFIG, _planner
from worker.sandbox import isolation
from worker.sandbox.dry_run import tiny_area
from worker.sandbox.isolation import SandboxLimits
from worker.sandbox.proxy import SandboxedPlanner, SandboxError

# Through libc, past the audit hook: the boundary is what is tested, not the diagnostic.
HOSTILE = {
    # The worker's environment (its secret key), the container's init's, and the database the
    # container reaches on the host's network.
    "looks for secrets and the network": """
libc = ctypes.CDLL(None, use_errno=True)
found = {'env': sorted(os.environ)}
try:
    found['init_env'] = open('/proc/1/environ', 'rb').read().decode(errors='replace')
except OSError as exc:
    found['init_env'] = type(exc).__name__
fd = libc.socket(2, 1, 0)
address = bytes([2, 0, 0x15, 0x38, 127, 0, 0, 1]) + bytes(8)  # AF_INET 127.0.0.1:5432
connected = libc.connect(fd, address, 16) if fd >= 0 else -1
found['connect'] = (connected, os.strerror(ctypes.get_errno()) if connected else None)
raise RuntimeError(repr(found))
""",
    "creates a user namespace": """
libc = ctypes.CDLL(None, use_errno=True)
result = libc.unshare(0x10000000)
raise RuntimeError(f'unshare gave {result} ({os.strerror(ctypes.get_errno())})')
""",
    "forks without end": "libc = ctypes.CDLL(None)\nwhile True:\n    libc.fork()",
    "allocates without end": "hog = []\nwhile True:\n    hog.append(bytearray(64 * 1024 * 1024))",
}
HONEST = "return Plan(np.array([[*obs.pose.position, obs.pose.yaw + 1.0]]))"


def fly(folder: Path, body: str) -> str:
    """Fly the planner whose `plan` is `body`; the reason its run ended."""
    code = folder / "code"
    code.mkdir(parents=True)
    (code / "planner.py").write_text(_planner(body))
    area, truth = tiny_area()
    # The project's numba kernels are compiled again in each planner process here (the
    # project is read-only, with no kernels cached), in its first calls: generous limits.
    limits = SandboxLimits(plan_timeout_s=30.0, memory_mib=512, processes=16)
    with SandboxedPlanner(code=code, limits=limits) as planner:
        try:
            result = run_episode(area, truth, planner, CONFIG, 0, seconds=4.0)
        except SandboxError as exc:
            return str(exc)
    return "succeeded" if result.status is RunStatus.SUCCEEDED else result.reason


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--probe-only", action="store_true")
    args = parser.parse_args()
    iso = isolation.probe()
    report: dict[str, object] = {"full": iso.full, "seccomp": iso.seccomp, "notes": iso.notes}
    try:
        isolation.require_full()
        report["uploads"] = "run"
    except isolation.SandboxUnavailableError as exc:
        report["uploads"] = f"refused: {exc}"
    # The container reaches the host's database (its network is the host's): a planner that
    # got out of its network namespace would too.
    with socket.socket() as probe_socket:
        probe_socket.settimeout(2)
        report["database_reachable_outside"] = probe_socket.connect_ex(("127.0.0.1", 5432)) == 0
    if iso.full and not args.probe_only:
        flights = {}
        with tempfile.TemporaryDirectory() as tmp:
            for index, (name, body) in enumerate({**HOSTILE, "honest": HONEST}.items()):
                flights[name] = fly(Path(tmp) / str(index), body)
        report["flights"] = flights
    print(json.dumps(report), flush=True)


if __name__ == "__main__":
    main()
