"""The benchmark's version and the fingerprints of its planners, held to a lock file.

A result is comparable with another only if both were made by the same simulator, metrics,
presets and areas, and by the same planner code. This module names that code:

- `component_hashes()`: one SHA-256 per component of the benchmark,

  - ``sim``: every ``*.py`` file under the `sim` package (the simulator and the metrics),
    subpackages included;
  - ``presets``: the canonical JSON of ``sim.config.PRESETS`` (each preset's ``model_dump``);
  - ``areas``: the sources of ``areas/registry.py`` and ``areas/ground_truth.py`` and of every
    module under ``areas/`` they import, transitively (the generators of the built-in areas are
    imported by the registry), plus the canonical JSON of each built-in area's name, generator
    and parameters (layout seed included);
  - ``libraries``: the installed versions of the libraries whose numbers shape a flight
    (``FLIGHT_LIBRARIES``: numpy, numba, Open3D, pybullet, ruckig, SciPy), and the CPU
    kernels they are pinned to (`flybo.cpu_kernels`). The same code flies differently with
    another release of one of them, so they are pinned exactly in ``pyproject.toml``, and an
    environment with other releases runs a ``+modified`` version.

- `benchmark_version()`: the short human name of those components (``2026.12-1``: year, month,
  and a counter), read from the lock file. When the tree's components differ from the lock's,
  the name gets the suffix ``+modified.<8 hex digits of the tree's components>``, and without a
  lock file the name is ``unlocked+<digits>``: a result is never labelled with a version whose
  code it was not made with.

- `planner_fingerprint(planner_id)`: a SHA-256 over the planner's class (module and qualified
  name), the canonical JSON of its default configuration, and the sources of its dependencies:
  the modules defining the class, its config model and their bases, and every module they
  import transitively (imports inside functions included) that lies in the `planners` package,
  in the top-level package of the planner's own module (a third-party planner's), or is
  ``sim/interface.py``. Other `sim` modules are left to the ``sim`` component, and the
  catalogue modules ``planners/registry.py`` and ``planners/builtin.py`` are not followed.
  Imports are read from the sources (`ast`), never executed.

Sources are read as UTF-8 with line endings normalised to ``\\n`` and named by their path
relative to the folder holding their top-level package (``planners/aep.py``), so hashes are the
same on every checkout; ``__pycache__`` is never read.

The lock file, ``flybo/benchmark.lock.json``, records the version name, the component hashes and
the fingerprint of every built-in planner id. ``tests/test_versions.py`` fails when the tree no
longer matches it:

- a component changed: the benchmark version must be bumped, which
  ``python -m flybo.versions --write`` does (or ``--write --name NAME``). Only a change of the
  ``sim`` sources that leaves every flight and every measure bit-identical (a refactor, such as a
  faster kernel computing the same numbers) keeps the name: ``--write --refactor``. The stored
  flight fingerprints (``tests/sim/episode_fingerprints.py``) are the evidence it must pass; a
  changed preset, area or library is never a refactor;
- a planner's fingerprint changed: its id must keep the code its results were made with, so
  the change is registered as a new version beside it (``planners/builtin.py``); a change that
  leaves every result bit-identical (a refactor) is accepted with ``--write``;
- a planner id was removed: ids stay registered (``--write`` refuses unless
  ``--allow-removal``);
- a planner id was added: ``--write`` records it.

``python -m flybo.versions`` prints the tree's versions, ``--check`` exits 1 listing every
mismatch, ``--write`` updates the lock and prints what changed.

The hashes are computed in `flybo.fingerprints`, from the sources that `flybo.module_sources`
finds and reads; this module re-exports them and keeps the lock.
"""

from __future__ import annotations

import argparse
import datetime
import json
import re
import sys
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from flybo.fingerprints import (
    COMPONENTS,
    component_hashes,
    fingerprint_of_class,
    planner_fingerprint,
    planner_fingerprints,
    sha256_of,
)
from flybo.module_sources import package_sources, read_source

__all__ = [
    "COMPONENTS",
    "LOCK_PATH",
    "REFACTORABLE",
    "WRITE_COMMAND",
    "benchmark_version",
    "check_lock",
    "component_hashes",
    "current_lock",
    "fingerprint_of_class",
    "load_lock",
    "main",
    "next_version",
    "package_sources",
    "planner_fingerprint",
    "planner_fingerprints",
    "read_source",
    "write_lock",
]

LOCK_PATH = Path(__file__).with_name("benchmark.lock.json")
WRITE_COMMAND = "python -m flybo.versions --write"

# The components whose sources may change without a new version when every result stays
# bit-identical (`write_lock(refactor=True)`): the simulator's code. Presets and areas are the
# benchmark's definition, and another library release is other code.
REFACTORABLE = frozenset({"sim"})

_VERSION_NAME = re.compile(r"^(?P<year>\d{4})\.(?P<month>\d{2})-(?P<serial>\d+)$")


# -- the lock -------------------------------------------------------------------------------------


def load_lock(path: Path | None = None) -> dict[str, Any] | None:
    """The contents of the lock file (`LOCK_PATH` unless `path`), or None when there is none."""
    try:
        return dict(json.loads(read_source(path or LOCK_PATH)))
    except FileNotFoundError:
        return None


def current_lock(benchmark_version: str) -> dict[str, Any]:
    """What the lock file would hold for this tree under version name `benchmark_version`."""
    return {"benchmark_version": benchmark_version, "components": component_hashes(),
            "planners": planner_fingerprints()}


def _components_digest(components: dict[str, str]) -> str:
    return sha256_of(components)[:8]


def benchmark_version() -> str:
    """The benchmark version of this tree: the lock's name, marked when the tree differs."""
    return _version_of(load_lock(), component_hashes())


def _version_of(lock: dict[str, Any] | None, components: dict[str, str]) -> str:
    if lock is None:
        return f"unlocked+{_components_digest(components)}"
    name = str(lock.get("benchmark_version", "unnamed"))
    if lock.get("components") != components:
        return f"{name}+modified.{_components_digest(components)}"
    return name


def next_version(name: str, today: datetime.date | None = None) -> str:
    """The version name after `name`: this month's first, or the next of the same month."""
    today = today or datetime.datetime.now(datetime.UTC).date()
    month = f"{today.year:04d}.{today.month:02d}"
    match = _VERSION_NAME.match(name)
    if match is None:
        return f"{month}-1"
    if (int(match["year"]), int(match["month"])) >= (today.year, today.month):
        return f"{match['year']}.{match['month']}-{int(match['serial']) + 1}"
    return f"{month}-1"


def _next_planner_id(planner_id: str, known: Iterable[str]) -> str:
    from planners.registry import format_id, parse_id

    name, _ = parse_id(planner_id)
    versions = [v for i in known for n, v in [parse_id(i)] if n == name and v is not None]
    return format_id(name, max(versions, default=0) + 1)


def check_lock(lock: dict[str, Any], components: dict[str, str],
               planners: dict[str, str]) -> list[str]:
    """Every way in which the tree (`components`, `planners`) differs from `lock`, each with
    what to do about it; empty when they match."""
    problems: list[str] = []
    name = str(lock.get("benchmark_version", ""))
    if not _VERSION_NAME.match(name):
        problems.append(f"the lock's benchmark version {name!r} is not of the form YYYY.MM-N: "
                        f"set one with `{WRITE_COMMAND} --name {next_version(name)}`")
    locked_components = dict(lock.get("components", {}))
    changed = [c for c in sorted(set(components) | set(locked_components))
               if locked_components.get(c) != components.get(c)]
    for component in changed:
        problems.append(
            f"component {component!r} changed since benchmark version {name}, which was not "
            f"bumped (lock {str(locked_components.get(component))[:12]}, tree "
            f"{str(components.get(component))[:12]}): bump it to {next_version(name)} with "
            f"`{WRITE_COMMAND}` (or choose the name: `{WRITE_COMMAND} --name NAME`)"
            + (f"; only if every result stays bit-identical (a refactor), keep the name with "
               f"`{WRITE_COMMAND} --refactor`" if component in REFACTORABLE else ""))
    locked_planners = dict(lock.get("planners", {}))
    known = set(locked_planners) | set(planners)
    for planner_id in sorted(known):
        old, new = locked_planners.get(planner_id), planners.get(planner_id)
        if new is None:
            problems.append(
                f"planner {planner_id} was removed: a released id stays registered, since "
                f"results name it; register it again (planners/builtin.py)")
        elif old is None:
            problems.append(f"planner {planner_id} is new: record it with `{WRITE_COMMAND}`")
        elif old != new:
            problems.append(
                f"planner {planner_id} changed: register it as "
                f"{_next_planner_id(planner_id, known)} and keep {planner_id} as it was "
                f"(planners/builtin.py); only if every result of {planner_id} stays "
                f"bit-identical (a refactor), accept the new code with `{WRITE_COMMAND}`")
    return problems


def _write(path: Path, content: dict[str, Any]) -> None:
    text = json.dumps(content, indent=2, sort_keys=True, ensure_ascii=False) + "\n"
    path.write_text(text, encoding="utf-8", newline="\n")


def write_lock(path: Path | None = None, *, name: str | None = None,
               allow_removal: bool = False, refactor: bool = False,
               today: datetime.date | None = None) -> list[str]:
    """Bring the lock file (`LOCK_PATH` unless `path`) up to date with the tree; the lines say
    what changed.

    The version name is bumped (`next_version`) when a component changed, unless `name` is
    given, or `refactor` is set and only components in `REFACTORABLE` changed: then the name
    stays, the change being declared bit-identical in every result.

    Raises:
        ValueError: a planner id would be removed without `allow_removal`, or `name` is the
            lock's name although a component changed, or is not of the form YYYY.MM-N, or
            `refactor` is set with `name` or with a changed component outside `REFACTORABLE`.
    """
    path = path or LOCK_PATH
    old = load_lock(path) or {}
    old_name = str(old.get("benchmark_version", ""))
    components, planners = component_hashes(), planner_fingerprints()
    old_components = dict(old.get("components", {}))
    old_planners = dict(old.get("planners", {}))
    changed = [c for c in COMPONENTS if old_components.get(c) != components[c]]
    removed = sorted(set(old_planners) - set(planners))
    if removed and not allow_removal:
        raise ValueError(f"planner ids {', '.join(removed)} are locked but no longer registered; "
                         "register them again, or pass --allow-removal if they were never "
                         "released")
    if refactor:
        if name is not None:
            raise ValueError("a refactor keeps the version name: give --refactor or --name")
        definition = [c for c in changed if c not in REFACTORABLE]
        if definition:
            raise ValueError(f"{', '.join(definition)} changed: what a run flies or measures "
                             f"changed, which is never a refactor; bump the version")
    if name is not None:
        if not _VERSION_NAME.match(name):
            raise ValueError(f"benchmark version {name!r} is not of the form YYYY.MM-N")
        if changed and name == old_name:
            raise ValueError(f"{', '.join(changed)} changed: the benchmark version must change "
                             f"from {old_name}")
        new_name = name
    elif (changed and not refactor) or not _VERSION_NAME.match(old_name):
        new_name = next_version(old_name, today)
    else:
        new_name = old_name
    lines = []
    for component in changed:
        what = "new" if component not in old_components else "changed"
        if refactor and component in old_components:
            what = "changed, accepted as a refactor"
        lines.append(f"component {component}: {what} ({str(old_components.get(component))[:12]}"
                     f" -> {components[component][:12]})")
    for planner_id in sorted(set(old_planners) | set(planners)):
        before, after = old_planners.get(planner_id), planners.get(planner_id)
        if before == after:
            continue
        if after is None:
            lines.append(f"planner {planner_id}: removed")
        elif before is None:
            lines.append(f"planner {planner_id}: added")
        else:
            lines.append(f"planner {planner_id}: CHANGED - accepted as a refactor; if its results "
                         f"differ, register the change as a new version instead")
    if new_name != old_name:
        lines.append(f"benchmark version: {old_name or '(none)'} -> {new_name}")
    content = {"benchmark_version": new_name, "components": components, "planners": planners}
    if content != old:
        _write(path, content)
    return lines


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m flybo.versions",
        description="The benchmark version and planner fingerprints of this tree, and the lock "
        "file that records them.")
    action = parser.add_mutually_exclusive_group()
    action.add_argument("--write", action="store_true", help="update the lock file")
    action.add_argument("--check", action="store_true",
                        help="exit 1 when the tree differs from the lock file")
    parser.add_argument("--name", help="with --write: the new benchmark version name")
    parser.add_argument("--allow-removal", action="store_true",
                        help="with --write: drop locked planner ids that are no longer registered")
    parser.add_argument("--refactor", action="store_true",
                        help="with --write: keep the version name for a change of the simulator's "
                        "sources that leaves every result bit-identical")
    parser.add_argument("--lock", type=Path, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    lock_path: Path = args.lock or LOCK_PATH
    if (args.name or args.allow_removal or args.refactor) and not args.write:
        parser.error("--name, --allow-removal and --refactor go with --write")
    if args.write:
        try:
            lines = write_lock(lock_path, name=args.name, allow_removal=args.allow_removal,
                               refactor=args.refactor)
        except ValueError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 1
        print("\n".join(lines) if lines else f"{lock_path.name} is up to date")
        return 0
    lock = load_lock(lock_path)
    if args.check:
        if lock is None:
            print(f"no lock file at {lock_path}: create it with `{WRITE_COMMAND}`",
                  file=sys.stderr)
            return 1
        problems = check_lock(lock, component_hashes(), planner_fingerprints())
        for problem in problems:
            print(problem, file=sys.stderr)
        return 1 if problems else 0
    components = component_hashes()
    print(f"benchmark version {_version_of(lock, components)}")
    for component, digest in components.items():
        print(f"  {component:<8} {digest}")
    for planner_id, digest in planner_fingerprints(builtin_only=False).items():
        print(f"  {planner_id:<16} {digest}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
