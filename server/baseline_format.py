"""The baseline dataset file: the results, series and reproducibility records of finished runs
of one benchmark version, without meshes or recordings (`docs/baselines.md`).

One JSON document, compressed with xz (LZMA). It names its format (`FORMAT`, `FORMAT_VERSION`)
and the benchmark version of every run in it; a reader refuses any other format version before
it looks further. Series are the database's own bytes (little-endian float32) in base64, so a
dataset loads back bit for bit; every other number is JSON's float64, also exact.
"""

from __future__ import annotations

import base64
import binascii
import json
import lzma
from datetime import datetime
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

FORMAT = "flybo-baselines"
FORMAT_VERSION = 2
# Version 1 is version 2 without the planners' `method`; both are read.
READABLE_VERSIONS = (1, 2)
SUFFIX = ".json.xz"
# A decompressed dataset larger than this is refused: the full suite is about 1/10 of it.
MAX_DECOMPRESSED_BYTES = 1 << 30
_XZ_PRESET = 9 | lzma.PRESET_EXTREME


class DatasetError(ValueError):
    """A file that is no readable baseline dataset of this format version (message: why)."""


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class PlannerEntry(_Strict):
    name: str = Field(min_length=1, max_length=64)
    version: int = Field(ge=1)
    builtin: bool
    description: str = ""
    reference: str = ""
    # `planners.fidelity`; format version 1 does not have it.
    method: Literal["original", "variant", ""] = ""
    code_hash: str = Field(default="", max_length=64)
    config: dict[str, Any] = Field(default_factory=dict)

    @property
    def key(self) -> str:
        return f"{self.name}-v{self.version}"


class AreaEntry(_Strict):
    name: str = Field(min_length=1, max_length=40)
    builtin: bool
    content_hash: str = Field(max_length=64)
    plateau_s: float = Field(gt=0)
    voxel_size: float = Field(gt=0)
    stats: dict[str, Any] = Field(default_factory=dict)


class SeriesEntry(_Strict):
    """A run's curves, each the base64 of little-endian float32 values."""

    time_s: str
    explored_volume_m3: str
    recall_time_s: str
    surface_recall: str

    @field_validator("time_s", "explored_volume_m3", "recall_time_s", "surface_recall")
    @classmethod
    def _float32(cls, value: str) -> str:
        try:
            raw = base64.b64decode(value, validate=True)
        except (binascii.Error, ValueError):
            raise ValueError("not base64") from None
        if len(raw) % 4:
            raise ValueError("not a whole number of float32 values")
        return value

    def blobs(self) -> dict[str, bytes]:
        return {k: base64.b64decode(getattr(self, k)) for k in type(self).model_fields}


class ResultEntry(_Strict):
    """The `run_results` row of a run, without its run id."""

    outcome: str = Field(max_length=16)
    reason: str
    simulated_until_s: float
    explored_volume_m3: float
    volume_at_plateau_m3: float
    observable_volume_m3: float
    coverage: float
    volumetric_efficiency: float
    precision: float | None
    recall: float | None
    fscore: float | None
    rmse_m: float | None
    collisions: int
    path_length_m: float
    iterations: int
    planning_ms_median: float | None
    planning_ms_mean: float | None
    planning_ms_max: float | None
    wall_seconds: float
    benchmark_version: str = Field(max_length=64)
    record: dict[str, Any] | None
    metrics: dict[str, Any] | None


class RunEntry(_Strict):
    planner: str = Field(description="name-vVERSION, one of the dataset's planners")
    area: str
    seed: int = Field(ge=0)
    preset: str = Field(min_length=1, max_length=32)
    seconds: float = Field(gt=0)
    attempts: int = Field(ge=0)
    worker: str | None = Field(default=None, max_length=128)
    sim_time_s: float
    enqueued_at: datetime | None
    started_at: datetime | None
    finished_at: datetime | None
    wall_time_s: float | None
    result: ResultEntry
    series: SeriesEntry | None

    @property
    def cell(self) -> tuple[str, str, str]:
        return self.planner, self.area, self.preset


class SuiteEntry(_Strict):
    """What the runs add up to. `wall_time_s`: from the first run's start to the last run's end
    (a service stopped meanwhile counts its pause); `run_wall_time_s`: the runs' own wall
    times summed."""

    runs: int
    simulated_s: float
    wall_time_s: float | None
    run_wall_time_s: float
    first_started_at: datetime | None
    last_finished_at: datetime | None


class Dataset(_Strict):
    format: str
    format_version: int
    benchmark_version: str = Field(min_length=1, max_length=64)
    exported_at: datetime
    suite: SuiteEntry
    planners: list[PlannerEntry]
    areas: list[AreaEntry]
    runs: list[RunEntry]

    def check_consistent(self) -> None:
        """Every run names a listed planner and area and is of the dataset's version; no
        (planner, area, preset, seed) twice."""
        planners = {p.key for p in self.planners}
        areas = {a.name for a in self.areas}
        seen: set[tuple[str, str, str, int]] = set()
        for i, run in enumerate(self.runs):
            where = f"run {i} ({run.planner} on {run.area}, seed {run.seed}, {run.preset})"
            if run.planner not in planners:
                raise DatasetError(f"{where}: planner {run.planner!r} is not in the dataset")
            if run.area not in areas:
                raise DatasetError(f"{where}: area {run.area!r} is not in the dataset")
            if run.result.benchmark_version != self.benchmark_version:
                raise DatasetError(f"{where}: made by benchmark version "
                                   f"{run.result.benchmark_version!r}, the dataset is of "
                                   f"{self.benchmark_version!r}")
            key = (*run.cell, run.seed)
            if key in seen:
                raise DatasetError(f"{where}: appears twice")
            seen.add(key)


def encode(dataset: Dataset) -> bytes:
    """The file's bytes."""
    text = dataset.model_dump_json(exclude_none=False)
    return lzma.compress(text.encode("utf-8"), format=lzma.FORMAT_XZ, preset=_XZ_PRESET)


def write_dataset(dataset: Dataset, path: Path) -> int:
    """Write `path` whole or not at all (a sibling file renamed into place); returns its size."""
    data = encode(dataset)
    part = path.with_name(f".{path.name}.part")
    part.write_bytes(data)
    part.replace(path)
    return len(data)


def _decompress(data: bytes) -> bytes:
    decompressor = lzma.LZMADecompressor(format=lzma.FORMAT_XZ)
    try:
        text = decompressor.decompress(data, max_length=MAX_DECOMPRESSED_BYTES)
    except lzma.LZMAError as exc:
        raise DatasetError(f"not an xz-compressed baseline dataset ({exc})") from None
    if not decompressor.eof:
        if decompressor.needs_input:
            raise DatasetError("the file ends early: it is a partial copy")
        raise DatasetError(f"larger than {MAX_DECOMPRESSED_BYTES >> 20} MiB decompressed")
    if decompressor.unused_data:
        raise DatasetError("unexpected bytes after the compressed data")
    return text


def decode(data: bytes, *, benchmark_version: str | None = None) -> Dataset:
    """Parse and check a dataset's bytes. With `benchmark_version`, a dataset of another
    benchmark version is refused; another format version always is."""
    try:
        raw = json.loads(_decompress(data))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise DatasetError(f"the compressed content is not JSON ({exc})") from None
    if not isinstance(raw, dict) or raw.get("format") != FORMAT:
        raise DatasetError(f"not a baseline dataset (no \"format\": \"{FORMAT}\")")
    found = raw.get("format_version")
    if found not in READABLE_VERSIONS:
        raise DatasetError(f"dataset format version {found!r}; this flybo reads format "
                           f"versions {', '.join(map(str, READABLE_VERSIONS))} only")
    found_version = raw.get("benchmark_version")
    if benchmark_version is not None and found_version != benchmark_version:
        raise DatasetError(f"dataset of benchmark version {found_version!r}; this service "
                           f"is benchmark version {benchmark_version!r} (results of different "
                           "versions are never ranked together)")
    try:
        dataset = Dataset.model_validate(raw)
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(p) for p in first.get("loc", ()))
        raise DatasetError(f"invalid dataset: {where}: {first.get('msg')} "
                           f"({exc.error_count()} problem(s))") from None
    dataset.check_consistent()
    return dataset


def read_dataset(path: Path, *, benchmark_version: str | None = None) -> Dataset:
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise DatasetError(f"cannot read {path}: {exc.strerror or exc}") from None
    return decode(data, benchmark_version=benchmark_version)
