"""The start-up check that flybo's top-level packages are the files flybo installed.

The wheel installs seven top-level packages whose names other distributions may use too
(`TOP_LEVEL`). In a shared environment pip would write both distributions into one folder (the
later one overwriting the other's files), and a folder of the same name earlier on `sys.path`
(the current folder under `python -m flybo`, `PYTHONPATH`, a `.pth` file) would shadow the
installed one; flybo would then run code that is not its own. `check` finds both, without
importing any of the packages, in about ten milliseconds; `main`, the `flybo` command, runs it
before anything else of the project is imported:

- installed from a wheel: each package resolves to the folder flybo's RECORD lists, its Python
  files have the recorded hashes and the folder holds no files of another distribution;
- an editable install: each package resolves to the project folder the install points at;
- no flybo distribution (a source tree on `sys.path`): all seven come from one folder.

Only when a check fails are all installed distributions searched (slow: every RECORD is read),
to name the one that took the name.
"""

from __future__ import annotations

import base64
import csv
import hashlib
import importlib.metadata as metadata
import importlib.util
import json
import os
import sys
from collections.abc import Iterable, Sequence
from pathlib import Path
from urllib.parse import unquote, urlparse

DISTRIBUTION = "flybo"
TOP_LEVEL = ("flybo", "areas", "sim", "planners", "server", "worker", "web")
_ADVICE = ("install flybo into a virtual environment of its own "
           "(python -m venv ENV && ENV/bin/pip install flybo), or remove the other one")


class DistributionClashError(RuntimeError):
    """A top-level package of flybo resolves to files flybo did not install."""


def main() -> None:
    """The `flybo` command (and `python -m flybo`): the check, then the command line; before
    the check no other package of the project is imported."""
    try:
        check()
    except DistributionClashError as exc:
        print(f"flybo: error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None
    from flybo.cli import main as cli_main

    cli_main()


def check(distribution: str = DISTRIBUTION, packages: Sequence[str] = TOP_LEVEL) -> None:
    """Raise `DistributionClashError` naming the clashing distribution or folder, if any."""
    try:
        dist = metadata.distribution(distribution)
    except metadata.PackageNotFoundError:
        dist = None
    record = _record(dist) if dist is not None and _editable_root(dist) is None else {}
    problems = [problem for name in packages
                for problem in _problems(dist, record, distribution, name, packages)]
    if problems:
        raise DistributionClashError("; ".join(problems) + f". To fix this, {_ADVICE}.")


def _problems(dist: metadata.Distribution | None, record: dict[str, str | None],
              distribution: str, name: str, packages: Sequence[str]) -> list[str]:
    folder = _package_dir(name)
    if folder is None:
        return [f"the package {name!r} cannot be found"]
    if dist is None:
        first = _package_dir(packages[0])
        if first is not None and folder.parent != first.parent:
            return [_foreign(name, folder, distribution)]
        return []
    editable = _editable_root(dist)
    if editable is not None:
        return [] if folder == editable / name else [_foreign(name, folder, distribution)]
    base = Path(str(dist.locate_file(""))).resolve()
    recorded = {path: digest for path, digest in record.items()
                if path.startswith(name + "/")}
    if not recorded:
        return [f"{distribution} {dist.version} lists no files of the package {name!r}"]
    if folder != base / name or f"{name}/__init__.py" not in recorded:
        return [_foreign(name, folder, distribution)]
    changed = [path for path, digest in recorded.items() if not _same(base / path, digest)]
    extra = [path for path in _files(folder, base) if path not in recorded]
    if not changed and not extra:
        return []
    owners = _owners(name, distribution, [base / path for path in [*changed, *extra]])
    example = (changed or extra)[0]
    if owners:
        return [f"files of the package {name!r} ({folder}) were replaced or added by "
                f"{_names(owners)} (e.g. {example})"]
    return [f"files of the package {name!r} ({folder}) were changed or added after "
            f"{distribution} installed them (e.g. {example})"]


def _record(dist: metadata.Distribution) -> dict[str, str | None]:
    """The files the distribution's RECORD lists (bytecode left out), relative to the folder
    it was installed into, with their hashes."""
    found: dict[str, str | None] = {}
    for row in csv.reader((dist.read_text("RECORD") or "").splitlines()):
        if row and "__pycache__/" not in row[0]:
            found[row[0]] = (row[1] if len(row) > 1 else "") or None
    return found


def _package_dir(name: str) -> Path | None:
    try:
        spec = importlib.util.find_spec(name)
    except (ImportError, ValueError):
        return None
    if spec is None or spec.origin is None or not spec.submodule_search_locations:
        return None  # missing, a namespace package or a plain module: not one of ours
    return Path(spec.origin).resolve().parent


def _editable_root(dist: metadata.Distribution) -> Path | None:
    try:
        info = json.loads(dist.read_text("direct_url.json") or "{}")
    except ValueError:
        return None
    url = info.get("url", "")
    if info.get("dir_info", {}).get("editable") and url.startswith("file:"):
        return Path(unquote(urlparse(url).path)).resolve()
    # The metadata a source checkout keeps beside its packages (`flybo.egg-info`), found first
    # when the checkout is the current folder (`python -m flybo` there): the checkout itself.
    base = Path(str(dist.locate_file(""))).resolve()
    if (base / "pyproject.toml").is_file() and (base / DISTRIBUTION / "__init__.py").is_file():
        return base
    return None


def _same(path: Path, digest: str | None) -> bool:
    if digest is None or path.suffix != ".py":
        return path.exists()
    mode, _, value = digest.partition("=")
    try:
        data = path.read_bytes()
        actual = hashlib.new(mode, data).digest()
    except (OSError, ValueError):
        return False
    return base64.urlsafe_b64encode(actual).rstrip(b"=").decode() == value


def _files(folder: Path, base: Path) -> Iterable[str]:
    """The files in `folder` (bytecode left out), relative to `base`."""
    prefix = len(str(base)) + 1
    for root, dirs, names in os.walk(folder):
        dirs[:] = [d for d in dirs if d != "__pycache__"]
        for file in names:
            yield os.path.join(root, file)[prefix:]


def _owners(name: str, distribution: str, paths: Sequence[Path]) -> list[str]:
    """The other installed distributions that list one of `paths` or install `name`."""
    wanted = set(paths)
    owners = []
    for dist in metadata.distributions():
        dist_name = dist.metadata["Name"] or "?"
        if dist_name.lower() == distribution.lower():
            continue
        tops = (dist.read_text("top_level.txt") or "").split()
        files = dist.files or []
        if name in tops or any(Path(str(dist.locate_file(f))).resolve() in wanted
                               for f in files if f.parts[0] == name):
            owners.append(f"{dist_name} {dist.version}")
    return sorted(set(owners))


def _names(owners: list[str]) -> str:
    return "the distribution " + " and ".join(owners)


def _foreign(name: str, folder: Path, distribution: str) -> str:
    owners = _owners(name, distribution, [folder / path for path in _files(folder, folder)])
    source = _names(owners) if owners else "a folder that no installed distribution owns"
    return (f"the package {name!r} is imported from {folder}, which {distribution} did not "
            f"install: it comes from {source}")
