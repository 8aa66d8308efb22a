"""What the benchmark scripts share: a results folder, table printing, and starting `flybo serve`
in a fresh data folder."""

from __future__ import annotations

import importlib.util
import json
import os
import platform
import resource
import shutil
import socket
import subprocess
import sys
import tempfile
import time
import types
from pathlib import Path
from typing import Any

import httpx

import flybo  # noqa: F401  before NumPy loads: it pins the CPU kernels (flybo.cpu_kernels)

RESULTS = Path(__file__).resolve().parent / "results"


def checked_baseline(baseline: Path | None, folder: str = "sim") -> Path | None:
    """A `--baseline` tree's folder, resolved, or None; exits naming the option when the folder
    holds no `folder/` (not a checkout of this project)."""
    if baseline is None:
        return None
    if not (baseline / folder).is_dir():
        raise SystemExit(f"--baseline {baseline}: not a checkout (no {folder}/ folder in it)")
    return baseline.resolve()


def baseline_module(baseline: Path, relative: str, name: str) -> types.ModuleType:
    """Another tree's module file `relative` (such as "sim/tsdf_points.py"), loaded as `name`.

    It runs from a copy in a temporary folder: numba's on-disk cache of its kernels then lives
    there, and names `name` as their module, so that the other tree's own cache (which its own
    runs load as `sim....`) is left alone. Its imports resolve to this tree's modules."""
    source = baseline / relative
    if not source.is_file():
        raise SystemExit(f"--baseline {baseline}: no {relative} in it")
    folder = Path(tempfile.mkdtemp(prefix="flybo-baseline-"))
    copy = folder / source.name
    shutil.copyfile(source, copy)
    spec = importlib.util.spec_from_file_location(name, copy)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    # Registered before it runs: numba's cache entries name the module they were compiled in.
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def peak_rss_mib() -> float:
    """Peak resident memory of this process so far, MiB."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def write_json(name: str, payload: dict[str, Any]) -> Path:
    RESULTS.mkdir(parents=True, exist_ok=True)
    path = RESULTS / f"{name}.json"
    payload = {"machine": {"python": platform.python_version(), "cpu": platform.processor(),
                           "system": platform.platform()}, **payload}
    path.write_text(json.dumps(payload, indent=2) + "\n")
    return path


def print_table(title: str, header: list[str], rows: list[list[Any]]) -> None:
    cells = [[str(c) for c in row] for row in rows]
    widths = [max(len(h), *(len(r[i]) for r in cells)) for i, h in enumerate(header)]
    print(f"\n{title}")
    print("  ".join(h.ljust(w) for h, w in zip(header, widths, strict=True)))
    print("  ".join("-" * w for w in widths))
    for row in cells:
        print("  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)))


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def service_env(data_dir: Path | str) -> dict[str, str]:
    """This environment without its `FLYBO_*` settings, with `data_dir` as the data folder (and
    the caller's cache folder, if set, so areas are not rebuilt)."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("FLYBO_")}
    env["FLYBO_DATA_DIR"] = str(data_dir)
    if "FLYBO_CACHE_DIR" in os.environ:
        env["FLYBO_CACHE_DIR"] = os.environ["FLYBO_CACHE_DIR"]
    return env


def create_token(env: dict[str, str], user: str) -> str:
    """A new API token for `user`, by `flybo tokens create` with the service's settings `env`."""
    return subprocess.run([sys.executable, "-m", "flybo", "tokens", "create", "--user", user],
                          env=env, check=True, capture_output=True, text=True).stdout.strip()


def wait_healthy(base: str, timeout_s: float = 120.0) -> float:
    """Seconds until `base`/healthz answers 200; SystemExit after `timeout_s`."""
    t0 = time.monotonic()
    while True:
        try:
            if httpx.get(f"{base}/healthz", timeout=2).status_code == 200:
                return time.monotonic() - t0
        except httpx.HTTPError:
            pass
        if time.monotonic() - t0 > timeout_s:
            raise SystemExit(f"flybo serve at {base} did not answer within {timeout_s:g} s")
        time.sleep(0.2)


def serve_command(tree: Path | None = None) -> tuple[list[str], Path | None]:
    """The command that runs `flybo` (and the folder to run it in): this checkout's, or the
    code of another `tree` (an unpacked `git archive` of an earlier commit, to measure before
    and after in one run). Another tree's code is imported from its folder, bypassing the
    installed distribution's check (which would name the folder a clash)."""
    if tree is None:
        return [sys.executable, "-m", "flybo"], None
    return [sys.executable, "-c", "from flybo.cli import main; main()"], tree
