"""What a stored run asks for (`RunSpec`), read in one query, and the area it flies in."""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from server.heldout import build_heldout_area, heldout_source
from server.models import HELDOUT_SPLIT, AreaRow, Job, PlannerRow, Run
from server.storage import ArtifactStore

if TYPE_CHECKING:
    from areas import Area


@dataclass(frozen=True)
class RunSpec:
    area: str
    area_file: str | None
    planner: str
    planner_builtin: bool
    planner_code: str | None  # artifact location of an uploaded planner's code
    planner_code_hash: str  # an uploaded planner's; "" for a built-in one
    planner_config: dict[str, Any]  # a built-in planner's default configuration
    preset: str
    seed: int
    seconds: float
    # A held-out area's (family, layout seed) (`server.heldout`); None for any other area.
    area_source: tuple[str, int] | None = None


def read_spec(factory: sessionmaker[Session], run_id: int) -> RunSpec:
    with factory() as session:
        run, area, planner = session.execute(
            select(Run, AreaRow, PlannerRow).join(AreaRow, Run.area_id == AreaRow.id)
            .join(Job, Run.job_id == Job.id).join(PlannerRow, Job.planner_id == PlannerRow.id)
            .where(Run.id == run_id)).one()
        defaults = planner.config.get("defaults") if planner.builtin else None
        return RunSpec(area.name, area.stats.get("file"), planner.key, planner.builtin,
                       planner.config.get("code"), planner.code_hash or "",
                       dict(defaults or {}), run.preset, run.seed, run.seconds,
                       heldout_source(area.stats) if area.split == HELDOUT_SPLIT else None)


def load_run_area(spec: RunSpec, store: ArtifactStore, folder: Path) -> Area:
    """The area: a built-in (or locally imported) one by name, or an uploaded one from `folder`
    (`Settings.areas_dir`), fetched from the artifact store first if this machine lacks it."""
    # The simulation stack (Open3D, numba) loads in the process that flies a run, not in
    # Celery's parent process before it forks its pool.
    from areas.registry import load_area
    from areas.store import AreaStoreError, load_stored_area

    if spec.area_source is not None:
        return _heldout_area(spec.area, *spec.area_source)
    if spec.area_file is None:
        return load_area(spec.area)
    try:
        return load_stored_area(spec.area, folder)
    except AreaStoreError:
        pass  # not on this machine yet, or damaged: fetch it again
    source = store.open_path(spec.area_file)
    target = folder / f"{spec.area}.npz"
    folder.mkdir(parents=True, exist_ok=True)
    part = folder / f".{spec.area}.{os.getpid()}.part"
    part.write_bytes(source.read_bytes())
    os.replace(part, target)
    return load_stored_area(spec.area, folder)


@functools.lru_cache(maxsize=4)
def _heldout_area(name: str, family: str, seed: int) -> Area:
    """A held-out area, built once per process (as `areas.registry.load_area` keeps the
    built-in ones)."""
    area: Area = build_heldout_area(name, family, seed)
    return area
