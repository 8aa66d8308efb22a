"""Python sources found and read without importing them: a module's file, the modules its source
imports (read with `ast`), the transitive closure of those, and every file of a package.

Sources are read as UTF-8 with line endings normalised to ``\\n`` and named by their path
relative to the folder holding their top-level package (``planners/aep.py``), so that what is
hashed from them is the same on every checkout; ``__pycache__`` is never read.
"""

from __future__ import annotations

import ast
import functools
import importlib.util
from collections.abc import Callable, Iterable
from pathlib import Path


def read_source(path: Path) -> str:
    """The text of a source file: UTF-8, line endings normalised to ``\\n``."""
    text = path.read_bytes().decode("utf-8")
    return text.replace("\r\n", "\n").replace("\r", "\n")


# Module-level so that tests can swap it: every source is read through `_read`.
_read: Callable[[Path], str] = read_source


@functools.cache
def top_level_location(top: str) -> Path | None:
    """The folder of package `top`, or the file of module `top`; None when it is not found."""
    try:
        found = importlib.util.find_spec(top)
    except (ImportError, ValueError):
        return None
    if found is None:
        return None
    if found.submodule_search_locations:
        return Path(next(iter(found.submodule_search_locations))).resolve()
    return Path(found.origin).resolve() if found.origin else None


def module_file(module: str) -> Path | None:
    """The source file of `module` (dotted name), without importing it; None when there is none.
    """
    top, _, rest = module.partition(".")
    base = top_level_location(top)
    if base is None:
        return None
    if base.is_file():
        return base if not rest and base.suffix == ".py" else None
    folder = base.joinpath(*rest.split(".")) if rest else base
    if rest and (candidate := folder.parent / f"{folder.name}.py").is_file():
        return candidate
    init = folder / "__init__.py"
    return init if init.is_file() else None


def relative_name(module: str, path: Path) -> str:
    """`path` relative to the folder holding `module`'s top-level package, with '/'."""
    base = top_level_location(module.partition(".")[0])
    assert base is not None
    return path.relative_to(base.parent).as_posix()


@functools.lru_cache(maxsize=1024)
def imports_of(module: str, is_package: bool, source: str) -> frozenset[str]:
    """Every module `source` (of `module`, a package's ``__init__`` if `is_package`) imports,
    anywhere in the file."""
    package = module if is_package else module.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(ast.parse(source, filename=module)):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".") if package else []
                if node.level - 1 > len(parts):
                    continue
                parts = parts[: len(parts) - (node.level - 1)]
                base = ".".join([*parts, *([node.module] if node.module else [])])
            else:
                base = node.module or ""
            if not base:
                continue
            found.add(base)
            # `from package import name` may import the submodule `package.name`.
            found.update(f"{base}.{alias.name}" for alias in node.names if alias.name != "*")
    return frozenset(found)


def closure(roots: Iterable[str], follow: Callable[[str], bool]) -> dict[str, tuple[str, str]]:
    """{module: (relative path, source)} of `roots` and of every module they import
    transitively for which `follow` is true and a source file exists."""
    seen: dict[str, tuple[str, str]] = {}
    pending = [m for m in roots if follow(m)]
    while pending:
        module = pending.pop()
        if module in seen:
            continue
        path = module_file(module)
        if path is None or "__pycache__" in path.parts:
            continue
        source = _read(path)
        seen[module] = (relative_name(module, path), source)
        imported = imports_of(module, path.name == "__init__.py", source)
        pending.extend(m for m in imported if follow(m) and m not in seen)
    return seen


def sorted_sources(modules: dict[str, tuple[str, str]]) -> list[list[str]]:
    """[relative path, source] of each of `modules` (as `closure` gives them), sorted by path."""
    return [[rel, text] for rel, text in sorted(modules.values())]


def package_sources(package: str) -> list[list[str]]:
    """[relative path, source] of every ``*.py`` file under `package`, sorted by path."""
    base = top_level_location(package)
    if base is None or not base.is_dir():
        raise RuntimeError(f"package {package!r} not found")
    files = [p for p in base.rglob("*.py") if "__pycache__" not in p.relative_to(base).parts]
    return sorted([p.relative_to(base.parent).as_posix(), _read(p)] for p in files)
