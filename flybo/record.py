"""The reproducibility record: what produced a run, stored with it (`result.json`'s
``reproducibility`` block, the database, the API, the run page and `flybo report`).

It names the code (package version, git commit when there is one, a hash of the sources of
`sim`, `planners` and `areas`), the benchmark version and its component hashes, the preset
(name and content hash), the area (name, generator, content hash), the planner (id, config hash,
code fingerprint), the seed, the libraries that shape the numbers and the machine (CPU model,
cores, the speed factor the planning charge used). A record that cannot be completed (no git,
a library without a version) keeps what it has and lists the rest in ``missing``: making the
record never fails a run.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.metadata
import json
import os
import platform
import subprocess
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from areas.area import Area
from flybo import versions
from flybo.cpu_kernels import blas_kernels, numpy_simd
from flybo.fingerprints import FLIGHT_LIBRARIES
from sim.config import EpisodeConfig

RECORD_VERSION = 1
LIBRARIES = FLIGHT_LIBRARIES
_SOURCE_PACKAGES = ("sim", "planners", "areas")
_ROOT = Path(__file__).resolve().parents[1]


def _sha256(value: Any) -> str:
    text = json.dumps(value, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def config_hash(config: EpisodeConfig | Mapping[str, Any]) -> str:
    """SHA-256 of a preset's or a planner config's canonical JSON."""
    data = config.model_dump(mode="json") if isinstance(config, EpisodeConfig) else dict(config)
    return _sha256(data)


def _git_commit() -> dict[str, Any]:
    if not (_ROOT / ".git").exists():
        raise LookupError("not a git checkout")
    def git(*args: str) -> str:
        return subprocess.run(["git", "-C", str(_ROOT), *args], capture_output=True, text=True,
                              check=True, timeout=10).stdout.strip()
    return {"commit": git("rev-parse", "HEAD"), "dirty": bool(git("status", "--porcelain",
                                                                  "--", *_SOURCE_PACKAGES))}


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    model = platform.processor()
    if not model:
        raise LookupError("no CPU model reported")
    return model


@functools.cache
def _process_code() -> tuple[dict[str, Any], dict[str, Any], tuple[str, ...]]:
    """The code this process runs, read once: what a process has imported is what its runs
    were made with, whatever happens to the files later."""
    gaps: list[str] = []

    def attempt(name: str, fn: Callable[[], Any]) -> Any:
        try:
            return fn()
        except Exception as exc:
            gaps.append(f"{name}: {type(exc).__name__}: {exc}")
            return None

    code = {
        "package_version": attempt("package_version", lambda: importlib.metadata.version("flybo")),
        "git": attempt("git", _git_commit),
        "sources_sha256": attempt("sources_sha256", lambda: _sha256(
            {p: versions.package_sources(p) for p in _SOURCE_PACKAGES})),
    }
    benchmark = {"benchmark_version": attempt("benchmark_version", versions.benchmark_version),
                 "components": attempt("components", versions.component_hashes)}
    return code, benchmark, tuple(gaps)


@functools.lru_cache(maxsize=256)
def _planner_fingerprint(planner_id: str) -> str:
    return versions.planner_fingerprint(planner_id)


def reproducibility_record(
    *,
    area: Area,
    planner_id: str,
    planner_config: Mapping[str, Any],
    preset_name: str,
    preset: EpisodeConfig,
    seed: int,
    speed_factor: float | None,
    planner_fingerprint: str | None = None,
) -> dict[str, Any]:
    """The record of one run. `planner_fingerprint` defaults to the registered id's; an uploaded
    planner passes the hash of its code."""
    missing: list[str] = []

    def attempt(name: str, fn: Callable[[], Any]) -> Any:
        try:
            return fn()
        except Exception as exc:  # a record keeps what it can; a gap never fails a run
            missing.append(f"{name}: {type(exc).__name__}: {exc}")
            return None

    code, benchmark, gaps = _process_code()
    missing.extend(gaps)
    fingerprint = planner_fingerprint or attempt(
        "planner.code_sha256", lambda: _planner_fingerprint(planner_id))
    record = {
        "record_version": RECORD_VERSION,
        **benchmark,
        "code": code,
        "preset": {"name": preset_name, "sha256": config_hash(preset)},
        "area": {"name": area.name, "generator": area.cache_key, "sha256": area.content_hash},
        "planner": {"id": planner_id, "config_sha256": config_hash(planner_config),
                    "code_sha256": fingerprint},
        "seed": seed,
        "libraries": {"python": platform.python_version(),
                      **{lib: attempt(lib, functools.partial(importlib.metadata.version, lib))
                         for lib in LIBRARIES},
                      # Which OpenBLAS kernels and NumPy loops ran: they shape the numbers
                      # (`flybo.cpu_kernels`).
                      "openblas_kernels": attempt("openblas_kernels",
                                                  lambda: ",".join(blas_kernels())),
                      "numpy_simd": attempt("numpy_simd", lambda: ",".join(numpy_simd()))},
        "machine": {"cpu_model": attempt("cpu_model", _cpu_model),
                    "cores": os.cpu_count(), "speed_factor": speed_factor},
    }
    record["missing"] = missing
    return record
