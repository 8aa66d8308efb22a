"""A run's reproducibility record: the benchmark version it was made with, and what made it.

The record is built by `flybo.record.reproducibility_record`, which `flybo worker` installs
(`install_record_builder`: this package may not import `flybo`); without it, or when it fails,
the row keeps what the worker knows and says what is missing.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Any, Protocol

from server.models import UNKNOWN_VERSION
from worker.run_spec import RunSpec

if TYPE_CHECKING:
    from areas import Area
    from sim.config import EpisodeConfig
    from sim.result import EpisodeResult

log = logging.getLogger(__name__)


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


def build_record(spec: RunSpec, area: Area, result: EpisodeResult) -> dict[str, Any]:
    """The run's reproducibility record, by the installed builder; never raises. Without a
    builder, or when it fails, what the worker knows itself, with the gap in `missing`."""
    from sim.config import preset  # the simulation stack: in the process that flies runs

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
