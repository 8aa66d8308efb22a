"""Numba's cached kernels are dropped when any kernel source changes (`flybo.kernel_cache`):
numba alone keeps a kernel that calls another file's compiled function as it was compiled."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from flybo.kernel_cache import STAMP, drop_stale_kernels, kernel_package_dirs, sources_digest

REPO = Path(__file__).resolve().parents[1]


def _package(root: Path) -> Path:
    """A package whose kernel `caller.g` calls `callee.f`, in another file."""
    package = root / "crossfile"
    package.mkdir()
    (package / "__init__.py").write_text("")
    _callee(package, 1)
    (package / "caller.py").write_text(textwrap.dedent("""
        import numba

        from crossfile.callee import f

        @numba.njit(cache=True)
        def g():
            return f() + 100
    """))
    return package


def _callee(package: Path, answer: int) -> None:
    (package / "callee.py").write_text(textwrap.dedent(f"""
        import numba

        @numba.njit(cache=True)
        def f():
            return {answer}
    """))


def _run(root: Path, drop: bool) -> int:
    code = ("import sys\n"
            f"sys.path.insert(0, {str(root)!r})\n"
            "from pathlib import Path\n"
            "from flybo.kernel_cache import drop_stale_kernels\n"
            f"if {drop}: drop_stale_kernels([Path({str(root / 'crossfile')!r})])\n"
            "from crossfile.caller import g\n"
            "print(g())\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=REPO, timeout=300, check=True)
    return int(done.stdout.strip())


@pytest.mark.parametrize("drop", [False, True])
def test_a_kernel_calling_a_changed_file_runs_the_new_code_only_when_dropped(
        tmp_path: Path, drop: bool) -> None:
    package = _package(tmp_path)
    assert _run(tmp_path, drop) == 101
    assert list((package / "__pycache__").glob("caller.g-*.nbi")), "numba cached nothing"
    _callee(package, 2)  # the callee's file changes; the caller's does not
    # Without the check numba runs the callee as compiled before: the hazard this guards
    # (and the proof that the case with the check exercises it).
    assert _run(tmp_path, drop) == (102 if drop else 101)


def _tree(root: Path) -> tuple[Path, Path]:
    (root / "sub" / "__pycache__").mkdir(parents=True)
    (root / "__pycache__").mkdir()
    (root / "a.py").write_text("A = 1\n")
    (root / "sub" / "b.py").write_text("B = 1\n")
    return root / "__pycache__", root / "sub" / "__pycache__"


def _kernels(*folders: Path) -> list[str]:
    return sorted(p.name for f in folders for p in f.iterdir() if p.suffix in (".nbi", ".nbc"))


def test_every_folders_kernels_go_when_one_source_changes_and_stay_otherwise(
        tmp_path: Path) -> None:
    top, sub = _tree(tmp_path)
    for name in ("a.f-1.py311.nbi", "a.f-1.py311.1.nbc"):
        (top / name).write_bytes(b"old")
    (sub / "b.g-1.py311.nbi").write_bytes(b"old")
    (top / "a.cpython-311.pyc").write_bytes(b"bytecode")
    # No stamp yet: what is cached cannot be known current.
    assert drop_stale_kernels([tmp_path]) == 3
    assert _kernels(top, sub) == [] and (top / "a.cpython-311.pyc").exists()
    assert (top / STAMP).read_text().strip() == sources_digest([tmp_path])
    (top / "a.f-1.py311.nbi").write_bytes(b"new")
    (sub / "b.g-1.py311.nbi").write_bytes(b"new")
    assert drop_stale_kernels([tmp_path]) == 0
    assert _kernels(top, sub) == ["a.f-1.py311.nbi", "b.g-1.py311.nbi"]
    (tmp_path / "sub" / "b.py").write_text("B = 2\n")
    assert drop_stale_kernels([tmp_path]) == 2
    assert _kernels(top, sub) == []
    # A new folder of sources is stamped before numba writes there.
    (tmp_path / "new").mkdir()
    (tmp_path / "new" / "c.py").write_text("C = 1\n")
    drop_stale_kernels([tmp_path])
    assert (tmp_path / "new" / "__pycache__" / STAMP).is_file()


def test_a_folder_it_may_not_write_is_left_as_it_is(tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    top, _ = _tree(tmp_path)
    (top / "a.f-1.py311.nbi").write_bytes(b"old")

    def refuse(self: Path, missing_ok: bool = False) -> None:
        raise PermissionError(f"read-only: {self}")

    monkeypatch.setattr(Path, "unlink", refuse)
    assert drop_stale_kernels([tmp_path]) == 0
    assert (top / "a.f-1.py311.nbi").exists() and not (top / STAMP).exists()


def test_the_projects_kernel_folders_are_stamped_with_their_sources() -> None:
    """Importing `flybo` (the tests' conftest does) checked the project's own folders."""
    roots = kernel_package_dirs()
    assert {p.name for p in roots} == {"areas", "planners", "sim"}
    digest = sources_digest(roots)
    for root in roots:
        stamp = root / "__pycache__" / STAMP
        assert stamp.read_text().strip() == digest
