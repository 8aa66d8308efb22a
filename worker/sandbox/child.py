"""The planner process: loads the planner, then answers `reset` and `plan` over a pipe.

Run by `worker.sandbox.proxy` inside the isolation of `worker.sandbox.isolation`:
``python -m worker.sandbox.child --fd-in 3 --fd-out 4 --map FILE (--code DIR | --builtin ID)``.
After loading, an audit hook refuses network, process creation and writes outside the working
folder, so that a planner that tries gets a clear error message. The hook is a diagnostic, not a
security boundary: native code (numba, ctypes) goes past it, it does not look at reads, it lets
anything be written under /tmp, and Python code can reach and change its state. What contains
a planner is the isolation around this process (`worker.sandbox.isolation`); uploaded code runs
only where that is complete.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import shutil
import sys
import time
import traceback
from collections.abc import Mapping
from pathlib import Path
from types import MappingProxyType
from typing import IO, Any

WRITABLE_ROOTS = ("/sandbox/work", "/tmp")
# Read-only, and bound into the hook at its definition: turning the messages off takes more
# than `_BLOCKED_EVENTS.clear()`, though not much more (see the docstring).
_BLOCKED_EVENTS = MappingProxyType({
    "socket.connect": "network access is not allowed",
    "socket.bind": "network access is not allowed",
    "socket.sendto": "network access is not allowed",
    "socket.getaddrinfo": "network access is not allowed",
    "subprocess.Popen": "starting processes is not allowed",
    "os.system": "starting processes is not allowed",
    "os.exec": "starting processes is not allowed",
    "os.posix_spawn": "starting processes is not allowed",
    "os.spawn": "starting processes is not allowed",
    "os.fork": "starting processes is not allowed",
    "os.forkpty": "starting processes is not allowed",
    "os.kill": "signalling processes is not allowed",
})


class SandboxViolation(PermissionError):  # noqa: N818 - reads as what happened
    pass


def _audit(event: str, args: tuple[Any, ...], *,
           _blocked: Mapping[str, str] = _BLOCKED_EVENTS,
           _writable: tuple[str, ...] = WRITABLE_ROOTS) -> None:
    reason = _blocked.get(event)
    if reason is not None:
        raise SandboxViolation(f"sandbox: {reason} ({event})")
    if event == "open" and len(args) >= 2:
        path, mode = args[0], args[1]
        writing = isinstance(mode, str) and any(c in mode for c in "wax+")
        if isinstance(mode, int):
            writing = bool(mode & (os.O_WRONLY | os.O_RDWR | os.O_CREAT | os.O_APPEND))
        if writing and isinstance(path, str | bytes):
            target = os.path.realpath(os.fsdecode(path))
            if not target.startswith(_writable):
                raise SandboxViolation(f"sandbox: writing outside the working folder is not "
                                       f"allowed ({target})")


def _load_planner(args: argparse.Namespace) -> Any:
    from planners.api import Planner

    if args.builtin:
        from planners.registry import make

        return make(args.builtin)
    path = Path(args.code) / "planner.py"
    spec = importlib.util.spec_from_file_location("submitted_planner", path)
    if spec is None or spec.loader is None:
        raise ImportError(f"cannot load {path.name}")
    sys.path.insert(0, args.code)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    classes = [v for v in vars(module).values() if isinstance(v, type) and issubclass(v, Planner)
               and v is not Planner and v.__module__ == module.__name__]
    if len(classes) != 1:
        raise TypeError(f"planner.py must define exactly one Planner subclass, found "
                        f"{len(classes)}")
    return classes[0]()


def _load(stack: Any, shared: Any, message: dict[str, Any]) -> None:
    """Copy the boxes the runner reports changed from the shared layers into the mirror."""
    from sim.occupancy import IndexBox

    box = message.get("box")
    if box is not None:
        stack.occupancy.load(shared[0], IndexBox(tuple(box[0]), tuple(box[1])))
    surface = message.get("surface_box")
    if surface is not None:
        stack.surface.load(shared[1], shared[2], IndexBox(tuple(surface[0]), tuple(surface[1])))


def _serve(reader: IO[bytes], writer: IO[bytes], map_path: str, planner: Any) -> None:
    import numpy as np

    from worker.sandbox.mirror import MirrorStack
    from worker.sandbox.protocol import (
        MAX_MESSAGE_BYTES,
        decode_context,
        decode_observation,
        encode_plan,
        parse_message,
        write_message,
    )

    stack: MirrorStack | None = None
    shared: Any = None
    while True:
        line = reader.readline(MAX_MESSAGE_BYTES + 1)
        if not line:
            return
        message = parse_message(line)
        try:
            if message["op"] == "reset":
                grid = message["grid"]
                nx, ny, nz = (int(n) for n in grid["shape"])
                shape = (nx, ny, nz)
                shared = np.memmap(map_path, dtype=np.uint8, mode="r", shape=(3, *shape))
                stack = MirrorStack(grid["origin"], shape, float(grid["voxel_size"]),
                                    float(message["ctx"]["safety_radius_m"]))
                planner.reset(decode_context(message["ctx"]))
                reply: dict[str, Any] = {"ok": True}
            elif message["op"] == "sync" and stack is not None:
                _load(stack, shared, message)
                view = stack.view()
                view.traversable  # noqa: B018 - bring the trackers up to date now
                view.frontier  # noqa: B018
                continue  # no reply: the runner does not wait for syncs
            elif message["op"] == "plan" and stack is not None:
                started = time.perf_counter()
                _load(stack, shared, message)
                loaded = time.perf_counter()
                obs = decode_observation(message["obs"], stack.view())
                plan = planner.plan(obs)
                done = time.perf_counter()
                reply = {"ok": True, "plan": encode_plan(plan),
                         "timing_ms": {"map": 1000 * (loaded - started),
                                       "plan": 1000 * (done - loaded)}}
            else:
                reply = {"ok": False, "error": f"unexpected message {message.get('op')!r}"}
        except Exception as exc:
            traceback.print_exc(file=sys.stderr)
            reply = {"ok": False, "error": f"{type(exc).__name__}: {exc}"[:2000]}
        write_message(writer, reply)


def seed_cache(seed: str) -> None:
    """Copy the project's compiled numba kernels from `seed` (read-only) into the writable
    `NUMBA_CACHE_DIR`, before anything compiles: numba uses only a cache it may write to."""
    cache = os.environ.get("NUMBA_CACHE_DIR")
    if cache and os.path.isdir(seed):
        shutil.copytree(seed, cache, dirs_exist_ok=True)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--fd-in", type=int, required=True)
    parser.add_argument("--fd-out", type=int, required=True)
    parser.add_argument("--map", required=True)
    parser.add_argument("--numba-seed", required=True)
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--code")
    source.add_argument("--builtin")
    args = parser.parse_args()
    reader = os.fdopen(args.fd_in, "rb")
    writer = os.fdopen(args.fd_out, "wb")
    seed_cache(args.numba_seed)
    # The framework's own modules load before the hook, so that it judges planner code only.
    import planners.api  # noqa: F401
    import worker.sandbox.mirror  # noqa: F401
    import worker.sandbox.protocol as protocol

    try:
        sys.addaudithook(_audit)
        planner = _load_planner(args)
    except BaseException as exc:
        traceback.print_exc(file=sys.stderr)
        protocol.write_message(writer, {"ok": False,
                                        "error": f"loading the planner failed: "
                                                 f"{type(exc).__name__}: {exc}"[:2000]})
        return
    protocol.write_message(writer, {"ok": True, "loaded": True})
    _serve(reader, writer, args.map, planner)


if __name__ == "__main__":
    main()
