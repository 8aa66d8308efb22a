"""The benchmark version and planner fingerprints (`flybo.versions`) and the lock file."""

from __future__ import annotations

import datetime
import importlib
import sys
import textwrap
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

import flybo.fingerprints as fingerprints
import flybo.module_sources as module_sources
import flybo.versions as versions
from flybo.versions import (
    WRITE_COMMAND,
    benchmark_version,
    check_lock,
    component_hashes,
    load_lock,
    next_version,
    planner_fingerprint,
    planner_fingerprints,
    write_lock,
)

HEX64 = r"^[0-9a-f]{64}$"


@pytest.fixture(scope="module")
def tree() -> dict[str, Any]:
    """The tree's versions, computed once for the module."""
    return {"components": component_hashes(), "planners": planner_fingerprints()}


def _lock(tree: dict[str, Any], name: str = "2026.12-1") -> dict[str, Any]:
    return {"benchmark_version": name, "components": dict(tree["components"]),
            "planners": dict(tree["planners"])}


# -- the lock file --------------------------------------------------------------------------------


def test_lock_matches_the_tree(tree: dict[str, Any]) -> None:
    lock = load_lock()
    assert lock is not None, f"no lock file: create it with `{WRITE_COMMAND}`"
    problems = check_lock(lock, tree["components"], tree["planners"])
    assert not problems, "\n".join(problems)
    assert benchmark_version() == lock["benchmark_version"]


def test_lock_holds_every_builtin_planner_and_component(tree: dict[str, Any]) -> None:
    from planners.registry import specs

    assert set(tree["components"]) == {"sim", "presets", "areas", "libraries"}
    assert set(tree["planners"]) == {s.id for s in specs() if s.builtin}
    assert {"classic-v1", "aep-v1", "aep-v2"} <= set(tree["planners"])
    for digest in [*tree["components"].values(), *tree["planners"].values()]:
        assert len(digest) == 64 and int(digest, 16) >= 0


def test_the_flight_libraries_installed_are_the_pinned_releases() -> None:
    """The environment runs the benchmark version only with the releases `pyproject.toml` pins."""
    import tomllib

    pyproject = Path(__file__).resolve().parents[1] / "pyproject.toml"
    pins = {}
    for requirement in tomllib.loads(pyproject.read_text())["project"]["dependencies"]:
        name, sep, release = requirement.partition("==")
        if sep:
            pins[name.strip()] = release.strip()
    assert set(pins) == set(fingerprints.FLIGHT_LIBRARIES)
    assert fingerprints.library_versions() == pins


def test_another_library_release_is_another_version(tree: dict[str, Any],
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    installed = fingerprints.library_versions()
    monkeypatch.setattr(fingerprints, "library_versions",
                        lambda: {**installed, "numpy": installed["numpy"] + ".post1"})
    components = component_hashes()
    assert components["libraries"] != tree["components"]["libraries"]
    assert {k: v for k, v in components.items() if k != "libraries"} == {
        k: v for k, v in tree["components"].items() if k != "libraries"}
    (problem,) = check_lock(_lock(tree), components, tree["planners"])
    assert "component 'libraries' changed" in problem


@pytest.mark.parametrize("component", ["sim", "presets", "areas", "libraries"])
def test_changed_component_without_a_bump_names_it(tree: dict[str, Any], component: str) -> None:
    lock = _lock(tree)
    lock["components"][component] = "0" * 64
    (problem,) = check_lock(lock, tree["components"], tree["planners"])
    assert f"component {component!r} changed" in problem
    assert "2026.12-1" in problem and "not bumped" in problem
    assert "2026.12-2" in problem  # how to bump: to which name, with which command
    assert WRITE_COMMAND in problem


def test_changed_planner_must_be_registered_as_a_new_version(tree: dict[str, Any]) -> None:
    lock = _lock(tree)
    lock["planners"]["classic-v1"] = "0" * 64
    lock["planners"]["aep-v1"] = "1" * 64
    problems = check_lock(lock, tree["components"], tree["planners"])
    assert len(problems) == 2
    assert any(p.startswith("planner classic-v1 changed: register it as classic-v4")
               for p in problems), problems
    # The next version is after the newest one registered, not after the changed one.
    assert any(p.startswith("planner aep-v1 changed: register it as aep-v5")
               for p in problems), problems


def test_removed_planner_fails(tree: dict[str, Any]) -> None:
    lock = _lock(tree)
    lock["planners"]["ghost-v1"] = "2" * 64
    (problem,) = check_lock(lock, tree["components"], tree["planners"])
    assert problem.startswith("planner ghost-v1 was removed")


def test_added_planner_is_fine_after_write(tree: dict[str, Any], tmp_path: Path) -> None:
    lock = _lock(tree)
    del lock["planners"]["rapid-v1"]
    (problem,) = check_lock(lock, tree["components"], tree["planners"])
    assert "planner rapid-v1 is new" in problem and WRITE_COMMAND in problem
    path = tmp_path / "lock.json"
    versions._write(path, lock)
    lines = write_lock(path)
    assert lines == ["planner rapid-v1: added"]
    written = load_lock(path)
    assert written is not None
    assert written["benchmark_version"] == "2026.12-1"  # no component changed: no bump
    assert check_lock(written, tree["components"], tree["planners"]) == []


def test_malformed_version_name_fails(tree: dict[str, Any]) -> None:
    (problem,) = check_lock(_lock(tree, name="latest"), tree["components"], tree["planners"])
    assert "YYYY.MM-N" in problem


# -- writing the lock -----------------------------------------------------------------------------


def test_write_creates_bumps_and_refuses_removals(
    tree: dict[str, Any], tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
) -> None:
    path = tmp_path / "lock.json"
    lines = write_lock(path, today=datetime.date(2026, 12, 1))
    assert "benchmark version: (none) -> 2026.12-1" in lines
    assert load_lock(path) == _lock(tree)
    assert write_lock(path) == []  # up to date: nothing changes

    monkeypatch.setitem(fingerprints._COMPONENT_HASHES, "presets", lambda: "3" * 64)
    lines = write_lock(path, today=datetime.date(2026, 12, 20))
    assert lines[0].startswith("component presets: changed")
    assert lines[-1] == "benchmark version: 2026.12-1 -> 2026.12-2"
    with pytest.raises(ValueError, match="must change"):
        monkeypatch.setitem(fingerprints._COMPONENT_HASHES, "presets", lambda: "4" * 64)
        write_lock(path, name="2026.12-2")
    write_lock(path, name="2027.01-5")
    lock = load_lock(path)
    assert lock is not None and lock["benchmark_version"] == "2027.01-5"

    lock["planners"]["ghost-v1"] = "5" * 64
    versions._write(path, lock)
    with pytest.raises(ValueError, match="ghost-v1"):
        write_lock(path)
    assert write_lock(path, allow_removal=True) == ["planner ghost-v1: removed"]


def test_a_simulator_refactor_keeps_the_name_and_nothing_else_does(
    tree: dict[str, Any], tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    path = tmp_path / "lock.json"
    write_lock(path, name="2026.12-7")
    monkeypatch.setitem(fingerprints._COMPONENT_HASHES, "sim", lambda: "7" * 64)
    problems = check_lock(load_lock(path) or {}, component_hashes(), tree["planners"])
    assert len(problems) == 1 and "--refactor" in problems[0]
    with pytest.raises(ValueError, match="keeps the version name"):
        write_lock(path, name="2026.12-8", refactor=True)
    assert versions.main(["--write", "--refactor", "--lock", str(path)]) == 0
    assert "component sim: changed, accepted as a refactor" in capsys.readouterr().out
    lock = load_lock(path)
    assert lock is not None and lock["benchmark_version"] == "2026.12-7"
    assert lock["components"]["sim"] == "7" * 64
    assert check_lock(lock, component_hashes(), tree["planners"]) == []

    monkeypatch.setitem(fingerprints._COMPONENT_HASHES, "presets", lambda: "8" * 64)
    problems = check_lock(lock, component_hashes(), tree["planners"])
    assert len(problems) == 1 and "--refactor" not in problems[0]
    with pytest.raises(ValueError, match="presets changed: what a run flies or measures"):
        write_lock(path, refactor=True)
    assert load_lock(path) == lock  # refused: nothing written
    with pytest.raises(SystemExit):
        versions.main(["--check", "--refactor", "--lock", str(path)])


def test_command_line_check_and_write(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "lock.json"
    assert versions.main(["--check", "--lock", str(path)]) == 1
    assert versions.main(["--write", "--lock", str(path)]) == 0
    assert "planner classic-v1: added" in capsys.readouterr().out
    assert versions.main(["--check", "--lock", str(path)]) == 0
    assert versions.main(["--write", "--lock", str(path)]) == 0
    assert "up to date" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("name", "today", "expected"),
    [("2026.12-1", (2026, 12, 5), "2026.12-2"), ("2026.12-9", (2026, 12, 5), "2026.12-10"),
     ("2026.11-3", (2026, 12, 5), "2026.12-1"), ("2027.01-1", (2026, 12, 5), "2027.01-2"),
     ("", (2026, 12, 5), "2026.12-1"), ("nonsense", (2027, 2, 1), "2027.02-1")],
)
def test_next_version(name: str, today: tuple[int, int, int], expected: str) -> None:
    assert next_version(name, datetime.date(*today)) == expected


def test_benchmark_version_marks_a_modified_tree(monkeypatch: pytest.MonkeyPatch) -> None:
    lock = load_lock()
    assert lock is not None
    monkeypatch.setitem(fingerprints._COMPONENT_HASHES, "sim", lambda: "6" * 64)
    marked = benchmark_version()
    assert marked.startswith(f"{lock['benchmark_version']}+modified.")
    assert len(marked.rsplit(".", 1)[1]) == 8


def test_benchmark_version_without_a_lock(monkeypatch: pytest.MonkeyPatch,
                                          tmp_path: Path) -> None:
    monkeypatch.setattr(versions, "LOCK_PATH", tmp_path / "missing.json")
    assert benchmark_version().startswith("unlocked+")


# -- hashes ---------------------------------------------------------------------------------------


def test_hashes_are_stable(tree: dict[str, Any]) -> None:
    module_sources.imports_of.cache_clear()
    assert component_hashes() == tree["components"]
    assert planner_fingerprints() == tree["planners"]
    assert planner_fingerprint("classic-v1") == tree["planners"]["classic-v1"]
    assert planner_fingerprint(" Classic ") == tree["planners"]["classic-v3"]  # the default


def test_every_planner_id_has_its_own_fingerprint(tree: dict[str, Any]) -> None:
    assert len(set(tree["planners"].values())) == len(tree["planners"])


def _edited(target: str, edit: str) -> Any:
    real = module_sources.read_source

    def read(path: Path) -> str:
        text = real(path)
        return text + edit if path.as_posix().endswith(target) else text

    return read


def test_editing_a_planner_source_changes_its_fingerprint(
    tree: dict[str, Any], monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(module_sources, "_read", _edited("planners/classic.py", "\n# edited\n"))
    after = planner_fingerprints()
    assert after["classic-v1"] != tree["planners"]["classic-v1"]
    # Everything built on Classic changes with it; ESM does not use it.
    assert after["aep-v1"] != tree["planners"]["aep-v1"]
    assert after["splatplanner-v1"] != tree["planners"]["splatplanner-v1"]
    assert after["esm-ipp-v1"] == tree["planners"]["esm-ipp-v1"]
    assert component_hashes() == tree["components"]


def test_editing_the_planner_interface_changes_every_fingerprint(
    tree: dict[str, Any], monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(module_sources, "_read", _edited("sim/interface.py", "\n# edited\n"))
    after = planner_fingerprints()
    assert all(after[i] != tree["planners"][i] for i in after)
    assert component_hashes()["sim"] != tree["components"]["sim"]


@pytest.mark.parametrize(
    ("target", "component"),
    [("sim/occupancy.py", "sim"), ("areas/maze.py", "areas"), ("areas/primitives.py", "areas")],
)
def test_editing_a_component_source_changes_its_hash(
    tree: dict[str, Any], monkeypatch: pytest.MonkeyPatch, target: str, component: str,
) -> None:
    monkeypatch.setattr(module_sources, "_read", _edited(target, "\n# edited\n"))
    after = component_hashes()
    assert {c for c in after if after[c] != tree["components"][c]} == {component}


def test_a_default_config_is_part_of_the_fingerprint(
    tree: dict[str, Any], monkeypatch: pytest.MonkeyPatch,
) -> None:
    from planners.classic import Classic, ClassicConfig

    class Tweaked(ClassicConfig):
        min_cluster_size: int = 99

    monkeypatch.setattr(Classic, "config_model", Tweaked)
    assert planner_fingerprint("classic-v1") != tree["planners"]["classic-v1"]


# -- a planner package of its own -----------------------------------------------------------------


_PLANNER = '''
from planners.api import Plan, Planner
from zz_fp_pkg.helpers import reason


class Hover(Planner):
    def plan(self, obs):
        return Plan.finished(reason())
'''


@pytest.fixture
def planner_package(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """A third-party package `zz_fp_pkg` on sys.path, with a planner and a helper module."""
    root = tmp_path / "zz_fp_pkg"
    root.mkdir()
    (root / "__init__.py").write_text("", encoding="utf-8")
    (root / "planner.py").write_text(textwrap.dedent(_PLANNER), encoding="utf-8")
    (root / "helpers.py").write_text("def reason():\n    return 'hover'\n", encoding="utf-8")
    (root / "unused.py").write_text("x = 1\n", encoding="utf-8")
    monkeypatch.syspath_prepend(str(tmp_path))
    module_sources.top_level_location.cache_clear()
    yield root
    module_sources.top_level_location.cache_clear()
    for name in [m for m in sys.modules if m == "zz_fp_pkg" or m.startswith("zz_fp_pkg.")]:
        del sys.modules[name]


def test_fingerprint_follows_the_planners_own_package(planner_package: Path) -> None:
    cls = importlib.import_module("zz_fp_pkg.planner").Hover
    modules = {rel for rel, _ in fingerprints.planner_modules(cls).values()}
    assert {"zz_fp_pkg/planner.py", "zz_fp_pkg/helpers.py", "planners/api.py",
            "sim/interface.py"} <= modules
    assert "zz_fp_pkg/unused.py" not in modules
    assert not any(m.startswith("sim/") and m != "sim/interface.py" for m in modules)
    assert not any("__pycache__" in m for m in modules)

    first = versions.fingerprint_of_class(cls)
    assert versions.fingerprint_of_class(cls) == first
    (planner_package / "unused.py").write_text("x = 2\n", encoding="utf-8")
    assert versions.fingerprint_of_class(cls) == first
    (planner_package / "helpers.py").write_text("def reason():\n    return 'hover!'\n",
                                                encoding="utf-8")
    edited = versions.fingerprint_of_class(cls)
    assert edited != first
    # Line endings do not count.
    source = (planner_package / "helpers.py").read_text(encoding="utf-8")
    (planner_package / "helpers.py").write_bytes(source.replace("\n", "\r\n").encode())
    assert versions.fingerprint_of_class(cls) == edited


def test_package_sources_skip_pycache(planner_package: Path) -> None:
    cache = planner_package / "__pycache__"
    cache.mkdir()
    (cache / "stale.py").write_text("x = 3\n", encoding="utf-8")
    names = [rel for rel, _ in versions.package_sources("zz_fp_pkg")]
    assert names == ["zz_fp_pkg/__init__.py", "zz_fp_pkg/helpers.py", "zz_fp_pkg/planner.py",
                     "zz_fp_pkg/unused.py"]
