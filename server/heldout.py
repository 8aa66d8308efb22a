"""The held-out split: areas generated from layout seeds only this service knows.

Each area of `Settings.heldout_areas` has one held-out counterpart per benchmark version and
generation: its generator run with a seed derived by HMAC from the held-out key
(`Settings.heldout_key`), the benchmark version, the generation and the area's name, and named
opaquely (`heldout-` and eight hex digits of another HMAC). The family and seed are kept in the
row's stats, which only admins see (`server.split_access`). Rotating (`rotate`, `flybo heldout
rotate`) starts a new generation, whose areas are new rows: results on the old ones stay, filed
under their generation, and are never ranked with the new ones.

The registries import the simulation stack, so they are imported here only when called.
"""

from __future__ import annotations

import hashlib
import hmac
from typing import Any

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from server.catalog import upsert_area
from server.models import HELDOUT_SPLIT, AreaRow, HeldoutGeneration

NAME_PREFIX = "heldout-"
FAMILY_KEY, SEED_KEY = "family", "layout_seed"  # in a held-out row's stats: admins only


def _digest(key: bytes, *parts: str) -> bytes:
    return hmac.new(key, "\n".join(parts).encode(), hashlib.sha256).digest()


def heldout_seed(key: bytes, benchmark_version: str, generation: int, family: str) -> int:
    """The layout seed of `family`'s held-out area: 63 bits of an HMAC, never 0 (seed 0 is the
    public scene)."""
    seed = int.from_bytes(_digest(key, "seed", benchmark_version, str(generation), family)[:8],
                          "big") >> 1
    return seed or 1


def heldout_name(key: bytes, benchmark_version: str, generation: int, family: str) -> str:
    """The opaque name of `family`'s held-out area, telling nothing of its family or seed."""
    digest = _digest(key, "name", benchmark_version, str(generation), family)
    return NAME_PREFIX + digest.hex()[:8]


def current_generation(session: Session) -> int:
    """The held-out generation in use: the newest one rotated to, 1 before any rotation."""
    newest = session.scalar(select(func.max(HeldoutGeneration.id)))
    return int(newest) if newest is not None else 1


def rotate(session: Session, note: str = "") -> int:
    """Start the next generation of held-out seeds and return it. The areas of older ones keep
    their results, which are never ranked with the new generation's."""
    generation = current_generation(session) + 1
    session.add(HeldoutGeneration(id=generation, note=note))
    session.flush()
    return generation


def heldout_rows(session: Session, generation: int | None = None) -> list[AreaRow]:
    """The held-out areas stored for `generation` (every generation for None), by name."""
    query = select(AreaRow).where(AreaRow.split == HELDOUT_SPLIT)
    if generation is not None:
        query = query.where(AreaRow.heldout_generation == generation)
    return list(session.scalars(query.order_by(AreaRow.name)))


def ensure_heldout_areas(session: Session, key: bytes, benchmark_version: str,
                         families: list[str]) -> list[AreaRow]:
    """The rows of the current generation's held-out areas of `families`, each built on first
    use (seconds per area) and flushed in the caller's transaction."""
    generation = current_generation(session)
    rows = []
    for family in families:
        name = heldout_name(key, benchmark_version, generation, family)
        row = session.scalar(select(AreaRow).where(AreaRow.name == name))
        if row is None:
            seed = heldout_seed(key, benchmark_version, generation, family)
            row = upsert_area(session, build_heldout_area(name, family, seed), builtin=True)
            row.split, row.heldout_generation = HELDOUT_SPLIT, generation
            row.stats = {**row.stats, FAMILY_KEY: family, SEED_KEY: seed}
            session.flush()
        rows.append(row)
    return rows


def build_heldout_area(name: str, family: str, seed: int) -> Any:
    """`family`'s generator at `seed`, named `name` (what a worker flies)."""
    from areas.registry import generate_area  # the simulation stack, on use

    area = generate_area(family, seed)
    area.name = name
    # Its cache key would name the family and seed (in cache files and in the run's record);
    # without one, the content hash names its ground-truth cache, as for an imported area.
    area.cache_key = None
    return area


def heldout_source(stats: dict[str, Any]) -> tuple[str, int] | None:
    """(family, layout seed) of a held-out row's stats; None for any other area."""
    family, seed = stats.get(FAMILY_KEY), stats.get(SEED_KEY)
    if isinstance(family, str) and isinstance(seed, int):
        return family, seed
    return None
