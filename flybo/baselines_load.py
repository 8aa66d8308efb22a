"""Loading a baseline dataset into a service's database: `flybo baselines import`, and the
shipped dataset at `flybo serve`'s first start (`docs/baselines.md`)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from sqlalchemy.orm import Session, sessionmaker

    from server.baselines import Imported

# The dataset this repository ships: `flybo serve` loads it into an empty database.
SHIPPED_DATASET = Path(__file__).resolve().parent / "baselines.json.xz"


def current_benchmark_version() -> str:
    from flybo.versions import benchmark_version  # hashes the tree: on use

    return benchmark_version()


def load_file(factory: sessionmaker[Session], path: Path, benchmark_version: str, *,
              only_if_empty: bool = False) -> Imported | None:
    """Import the dataset at `path` in one transaction; with `only_if_empty`, only into a
    database without jobs (None otherwise). Raises `DatasetError`."""
    from server.baseline_format import DatasetError, decode
    from server.baselines import database_is_empty, fingerprint, import_dataset
    from server.db import session_scope

    try:
        data = path.read_bytes()
    except OSError as exc:
        raise DatasetError(f"cannot read {path}: {exc.strerror or exc}") from None
    dataset = decode(data, benchmark_version=benchmark_version)
    with session_scope(factory) as session:
        if only_if_empty and not database_is_empty(session):
            return None
        return import_dataset(session, dataset, fingerprint(data))


def load_shipped_baselines(factory: sessionmaker[Session],
                           path: Path = SHIPPED_DATASET) -> None:
    """`flybo serve`'s first start: the shipped dataset into an empty database. A dataset of
    another benchmark version is reported and left out; the service starts either way."""
    if not path.is_file():
        return
    from server.baseline_format import DatasetError

    try:
        done = load_file(factory, path, current_benchmark_version(), only_if_empty=True)
    except DatasetError as exc:
        print(f"flybo: the shipped baselines were not loaded: {exc}", file=sys.stderr)
        return
    if done is not None:
        print(f"loaded {done.imported} reference run(s) of benchmark version "
              f"{done.benchmark_version} from {path.name}", flush=True)
