"""Rows for the built-in (and stored) areas and planners, kept in step with the registries.

The registries import the simulation stack, so they are imported here only when called.
"""

from __future__ import annotations

import logging
from typing import Any

from sqlalchemy import select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session, sessionmaker

from server.models import AreaRow, PlannerRow

log = logging.getLogger(__name__)


class CatalogError(LookupError):
    """A name that no registry knows."""


def area_stats(area: Any) -> dict[str, Any]:
    extent = area.bounds_max - area.bounds_min
    info = area.info
    return {
        "title": info.title, "rooms": info.rooms, "levels": info.levels,
        "complexity": info.complexity, "indoor": info.indoor,
        "bounding_volume_m": [round(float(x), 3) for x in extent],
        "faces": len(area.triangles),
        "start": [*(float(x) for x in area.start.position), float(area.start.yaw)],
    }


def upsert_area(session: Session, area: Any, *, builtin: bool,
                owner_id: int | None = None) -> AreaRow:
    row = session.scalar(select(AreaRow).where(AreaRow.name == area.name))
    values = {"builtin": builtin, "content_hash": area.content_hash,
              "plateau_s": float(area.plateau_s), "voxel_size": float(area.voxel_size),
              "stats": area_stats(area)}
    if row is None:
        try:
            # A savepoint: another process may insert the same built-in area at the same time.
            with session.begin_nested():
                row = AreaRow(name=area.name, owner_id=owner_id, **values)
                session.add(row)
        except IntegrityError:
            row = session.scalars(select(AreaRow).where(AreaRow.name == area.name)).one()
    elif row.content_hash != area.content_hash or row.stats != values["stats"]:
        for key, value in values.items():
            setattr(row, key, value)
    session.flush()
    return row


def ensure_area(session: Session, name: str) -> AreaRow:
    """The row of area `name`, created from the registry on first use."""
    row = session.scalar(select(AreaRow).where(AreaRow.name == name))
    if row is not None:
        return row
    from areas.registry import UnknownAreaError, area_names, load_area  # on use: see above

    try:
        area = load_area(name)
    except UnknownAreaError as exc:
        raise CatalogError(str(exc)) from None
    return upsert_area(session, area, builtin=name in area_names())


def sync_builtin_areas(factory: sessionmaker[Session]) -> None:
    """Rows for every built-in area. Each area is built first, then written in its own short
    transaction: building takes seconds, and SQLite allows one writer at a time."""
    from areas.registry import area_names, load_area  # the simulation stack, on use

    for name in area_names():
        area = load_area(name)
        with factory() as session:
            upsert_area(session, area, builtin=True)
            session.commit()


def sync_builtin_planners(session: Session) -> None:
    from planners.registry import planner_ids, spec  # the simulation stack, on use

    for planner_id in planner_ids():
        s = spec(planner_id)
        row = session.scalar(select(PlannerRow).where(PlannerRow.name == s.name,
                                                      PlannerRow.version == s.version))
        config = s.config_model.model_json_schema()
        defaults = s.config_model().model_dump(mode="json")
        if row is None:
            try:
                with session.begin_nested():
                    session.add(PlannerRow(name=s.name, version=s.version, builtin=True,
                                           description=s.description, reference=s.reference,
                                           method=s.method,
                                           config={"defaults": defaults, "schema": config}))
            except IntegrityError:
                pass  # another process registered it just now
        else:
            row.description, row.reference, row.method = s.description, s.reference, s.method
            row.config = {"defaults": defaults, "schema": config}
    session.flush()


def find_planner(session: Session, name: str) -> PlannerRow:
    """`name` (its default version: the registry's newest original, for a built-in planner;
    the newest, for an uploaded one) or `name-vN` (that version), in any case. A built-in planner's
    name is read by the planner registry, exactly as `flybo run --planner` reads it."""
    from planners.registry import UnknownPlannerError, spec  # the simulation stack, on use

    base, version = name.strip().lower(), None
    try:
        builtin = spec(base)
    except UnknownPlannerError:  # an uploaded planner (their names never clash with built-ins)
        head, _, tail = base.rpartition("-v")
        if head and tail.isdigit():
            base, version = head, int(tail)
    else:
        base, version = builtin.name, builtin.version
    query = select(PlannerRow).where(PlannerRow.name == base)
    if version is not None:
        query = query.where(PlannerRow.version == version)
    row = session.scalars(query.order_by(PlannerRow.version.desc())).first()
    if row is None:
        known = sorted({r.key for r in session.scalars(select(PlannerRow))})
        raise CatalogError(f"unknown planner {name!r}; known: {', '.join(known) or 'none'}")
    return row


def preset_names() -> list[str]:
    from sim.config import PRESETS  # the simulation stack, on use

    return sorted(PRESETS)
