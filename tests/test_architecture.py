"""The import rules between the project's packages, checked on the source with `ast`.

Every import counts: at module level, inside functions, under `if TYPE_CHECKING:`, relative or
absolute. `from x import y` is an import of the module `x.y` when that is a module of the
project, else of `x`. Importing a submodule is not counted as importing its parent package.

The layers, lowest first, as `docs/architecture.md` lists them: `areas`, `sim`, `planners`,
`server` (the API's library: never `web` nor `worker`), then `worker` and `web` (both may use
`server`, neither the other), and `flybo` (the entry points), which may use everything. So
`sim` and `areas` import none of `server`, `worker`, `web`, `flybo`, and `planners` none of
`server`, `worker`, `web`.
"""

from __future__ import annotations

import ast
import itertools
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("flybo", "areas", "sim", "planners", "server", "worker", "web")

# package -> the other packages it may import
ALLOWED: dict[str, frozenset[str]] = {
    "areas": frozenset(),
    "sim": frozenset({"areas"}),
    "planners": frozenset({"areas", "sim"}),
    "server": frozenset({"areas", "sim", "planners"}),
    "worker": frozenset({"areas", "sim", "planners", "server"}),
    "web": frozenset({"areas", "sim", "planners", "server"}),
    "flybo": frozenset(PACKAGES) - {"flybo"},
}

# Known cycles, each waiting for its fix in a package this file does not fix: the one import
# that closes it is left out of the cycle check, and `test_pending_cycles_are_still_there`
# fails once it is gone, so that the entry goes too.
PENDING_CYCLE_EDGES: dict[tuple[str, str], str] = {}


@dataclass(frozen=True)
class Import:
    source: str  # the importing module
    target: str  # the imported module of the project
    path: Path
    line: int

    def where(self) -> str:
        return f"{self.path.relative_to(ROOT)}:{self.line}"


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def project_modules() -> dict[str, Path]:
    modules: dict[str, Path] = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            modules[module_name(path)] = path
    return modules


def _resolve(name: str, modules: dict[str, Path]) -> str | None:
    """The project module `name` is, or lies in (`a.b.c` where only `a.b` is a module)."""
    while name:
        if name in modules:
            return name
        name = name.rpartition(".")[0]
    return None


def imports_of(module: str, path: Path, modules: dict[str, Path]) -> Iterator[Import]:
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    for node in ast.walk(tree):
        targets: list[str] = []
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".")
                keep = len(parts) - (node.level - 1)
                assert keep > 0, f"{path}:{node.lineno}: relative import beyond the top package"
                base = ".".join(parts[:keep] + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            for alias in node.names:
                child = f"{base}.{alias.name}"
                targets.append(child if child in modules else base)
        for name in targets:
            target = _resolve(name, modules)
            if target is not None and target != module:
                yield Import(module, target, path, node.lineno)


def all_imports() -> list[Import]:
    modules = project_modules()
    return [imp for module, path in modules.items() for imp in imports_of(module, path, modules)]


def find_cycle(edges: dict[str, set[str]]) -> list[str] | None:
    """One import cycle, as the list of modules along it (first == last), or None."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(edges.get(node, ())):
            if state.get(nxt) == 1:
                return [*stack[stack.index(nxt):], nxt]
            if nxt not in state and (found := visit(nxt)):
                return found
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(edges):
        if node not in state and (found := visit(node)):
            return found
    return None


@pytest.fixture(scope="module")
def imports() -> list[Import]:
    found = all_imports()
    assert found, "no imports found: is ROOT right?"
    return found


def test_every_module_parses_and_the_packages_are_there() -> None:
    modules = project_modules()
    for package in PACKAGES:
        assert package in modules, f"package {package} has no __init__.py under {ROOT}"


def test_the_rules_cover_every_package() -> None:
    assert set(ALLOWED) == set(PACKAGES)
    # The rules the layers rest on, spelled out.
    assert not ALLOWED["server"] & {"web", "worker"}
    for low in ("sim", "areas"):
        assert not ALLOWED[low] & {"server", "worker", "web", "flybo"}
    assert not ALLOWED["planners"] & {"server", "worker", "web"}


@pytest.mark.parametrize("package", PACKAGES)
def test_layers(imports: list[Import], package: str) -> None:
    allowed = ALLOWED[package] | {package}
    offending = sorted({f"  {imp.where()}: {imp.source} imports {imp.target}"
                        for imp in imports if imp.source.split(".")[0] == package
                        and imp.target.split(".")[0] not in allowed})
    may = ", ".join(sorted(ALLOWED[package])) or "no other package of the project"
    assert not offending, (
        f"{package} may import only {may} (docs/architecture.md); found:\n"
        + "\n".join(offending))


def _edges(imports: list[Import]) -> tuple[dict[str, set[str]], dict[tuple[str, str], Import]]:
    edges: dict[str, set[str]] = {}
    lines: dict[tuple[str, str], Import] = {}
    for imp in imports:
        edges.setdefault(imp.source, set()).add(imp.target)
        lines.setdefault((imp.source, imp.target), imp)
    return edges, lines


def _reaches(edges: dict[str, set[str]], start: str, goal: str) -> bool:
    seen, todo = {start}, [start]
    while todo:
        for nxt in edges.get(todo.pop(), ()):
            if nxt == goal:
                return True
            if nxt not in seen:
                seen.add(nxt)
                todo.append(nxt)
    return False


def test_no_import_cycle(imports: list[Import]) -> None:
    edges, lines = _edges(imports)
    for source, target in PENDING_CYCLE_EDGES:
        edges.get(source, set()).discard(target)
    cycle = find_cycle(edges)
    assert cycle is None, "import cycle: " + " -> ".join(cycle) + "\n" + "\n".join(
        f"  {lines[a, b].where()}: {a} imports {b}" for a, b in itertools.pairwise(cycle))


def test_pending_cycles_are_still_there(imports: list[Import]) -> None:
    edges, _ = _edges(imports)
    fixed = [f"{a} -> {b} ({why})" for (a, b), why in PENDING_CYCLE_EDGES.items()
             if b not in edges.get(a, ()) or not _reaches(edges, b, a)]
    assert not fixed, "no longer a cycle, remove from PENDING_CYCLE_EDGES: " + "; ".join(fixed)


def test_the_checker_sees_function_level_and_relative_imports(tmp_path: Path) -> None:
    """The checker itself: a lazy import and a relative one are both found."""
    modules = {"server": tmp_path / "server" / "__init__.py",
               "server.a": tmp_path / "server" / "a.py",
               "server.b": tmp_path / "server" / "b.py",
               "web": tmp_path / "web" / "__init__.py"}
    source = "from . import b\n\ndef f():\n    from web import x\n    import server.b.c\n"
    path = tmp_path / "server" / "a.py"
    path.parent.mkdir()
    path.write_text(source)
    found = {(imp.target, imp.line) for imp in imports_of("server.a", path, modules)}
    assert found == {("server.b", 1), ("web", 4), ("server.b", 5)}
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": {"c"}}) is None
