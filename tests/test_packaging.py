"""The wheel: built from the repository, installed (not editable) into a fresh virtual
environment, it serves (migrations included), flies an episode and runs the sandbox, all from
the installed files and none from the source tree.

The fresh environment gets the wheel only (`--no-deps`); its dependencies come from this test's
own environment through a `.pth` line. Such a line adds the folder to `sys.path` without running
the `.pth` files in it, so the editable install of the source tree there stays inert, and the
test checks that every project package is imported from the fresh environment.
"""

from __future__ import annotations

import base64
import hashlib
import os
import shutil
import signal
import socket
import subprocess
import sys
import sysconfig
import time
import tomllib
import zipfile
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

REPO = Path(__file__).resolve().parents[1]
TOP_LEVEL = ("flybo", "areas", "sim", "planners", "server", "worker", "web")
# What a build reads besides the packages.
BUILD_FILES = ("pyproject.toml", "README.md")
# Build and install only: the runs below start well under a minute.
TIMEOUT_S = 600


def _source_files() -> list[Path]:
    """The files a clone would have (tracked, or new and not ignored), relative to REPO."""
    if (REPO / ".git").exists():
        listed = subprocess.run(["git", "ls-files", "-z", "--cached", "--others",
                                 "--exclude-standard"], cwd=REPO, check=True,
                                capture_output=True).stdout.decode().split("\0")
        return [Path(p) for p in listed if p and (REPO / p).is_file()]
    found = [Path(name) for name in BUILD_FILES if (REPO / name).is_file()]
    return found + [p.relative_to(REPO) for top in (*TOP_LEVEL, "migrations") for p in
                    (REPO / top).rglob("*") if p.is_file() and "__pycache__" not in p.parts]


def _package_sources() -> set[str]:
    """The files the wheel must hold, as paths inside it (migrations/ goes into server/)."""
    wanted = set()
    for path in _source_files():
        if path.parts[0] in TOP_LEVEL:
            wanted.add(path.as_posix())
        elif path.parts[0] == "migrations":
            wanted.add(Path("server", *path.parts).as_posix())
    return wanted


def test_every_package_folder_is_listed_in_pyproject() -> None:
    config = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(config["packages"])
    found = {".".join(path.parent.parts) for path in _source_files()
             if path.parts[0] in TOP_LEVEL and path.name == "__init__.py"}
    assert found - listed == set(), "add these packages to [tool.setuptools] packages"
    assert config["package-dir"] == {"server.migrations": "migrations"}
    assert {"server.migrations", "server.migrations.versions"} <= listed


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def _run(args: list[str | Path], **kwargs: object) -> subprocess.CompletedProcess[str]:
    result = subprocess.run([str(a) for a in args], capture_output=True, text=True,
                            **kwargs)  # type: ignore[call-overload]
    assert result.returncode == 0, f"{args}\nstdout:\n{result.stdout}\nstderr:\n{result.stderr}"
    return result


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The wheel, built from a copy of the repository's files (never in the tree itself, where
    a stale build/ folder would leak into it and other builds may run at the same time)."""
    base = tmp_path_factory.mktemp("build")
    source = base / "source"
    for path in _source_files():
        if path.parts[0] in (*TOP_LEVEL, "migrations") or path.as_posix() in BUILD_FILES:
            (source / path).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(REPO / path, source / path)
    _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", base / "dist", source],
         timeout=TIMEOUT_S)
    (built,) = (base / "dist").glob("flybo-*.whl")
    return built


def _fresh_venv(root: Path, wheel: Path) -> Path:
    """A new environment holding the wheel; returns its `bin` folder."""
    _run([sys.executable, "-m", "venv", "--without-pip", root], timeout=TIMEOUT_S)
    python = root / "bin" / "python"
    _run([sys.executable, "-m", "pip", "--python", python, "install", "-q", "--no-deps",
          "--no-index", wheel], timeout=TIMEOUT_S)
    purelib = _run([python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"]
                   ).stdout.strip()
    # The dependencies: this environment's site-packages, after the fresh one's.
    (Path(purelib) / "flybo-test-dependencies.pth").write_text(
        sysconfig.get_paths()["purelib"] + "\n")
    return root / "bin"


def _env(tmp: Path) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("FLYBO_", "PYTHON", "VIRTUAL_ENV"))}
    env.update(FLYBO_DATA_DIR=str(tmp / "data"), FLYBO_CACHE_DIR=str(tmp / "cache"))
    return env


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory, wheel: Path) -> Path:
    return _fresh_venv(tmp_path_factory.mktemp("venv"), wheel)


@pytest.fixture
def cwd(tmp_path: Path) -> Path:
    """An empty working folder away from the repository."""
    folder = tmp_path / "cwd"
    folder.mkdir()
    return folder


@pytest.mark.slow
def test_the_wheel_holds_the_packages_and_migrations(wheel: Path) -> None:
    names = set(zipfile.ZipFile(wheel).namelist())
    assert _package_sources() - names == set()
    assert {"server/migrations/env.py", "server/migrations/script.py.mako"} <= names
    assert any(n.startswith("server/migrations/versions/0001_") for n in names)
    tops = {n.split("/")[0] for n in names if not n.startswith("flybo-")}
    assert tops == set(TOP_LEVEL)  # nothing else at the top level: no `migrations`, no `tests`


@pytest.mark.slow
def test_the_packages_come_from_the_fresh_environment(installed: Path, cwd: Path) -> None:
    venv = installed.parent.resolve()
    code = ("import importlib, sys\n"
            f"for name in {TOP_LEVEL!r}:\n"
            "    print(importlib.import_module(name).__file__)\n"
            "from server.migrate import migrations_dir\n"
            "print(migrations_dir() / 'env.py')\n"
            "from worker.sandbox import isolation\n"
            "print(*[p / '__init__.py' for p in isolation.package_dirs().values()], sep='\\n')\n")
    printed = _run([installed / "python", "-c", code], cwd=cwd, env=_env(cwd)).stdout.split()
    # The sandbox mounts sim, planners and worker (never areas: no ground truth in reach).
    assert len(printed) == len(TOP_LEVEL) + 1 + 3
    for path in map(Path, printed):
        assert path.resolve().is_relative_to(venv), path
        assert path.is_file()
        assert not path.resolve().is_relative_to(REPO)


@pytest.mark.slow
def test_serve_from_the_installed_wheel(installed: Path, cwd: Path) -> None:
    port = _free_port()
    env = _env(cwd)
    log = (cwd / "serve.log").open("w")
    proc = subprocess.Popen([installed / "flybo", "serve", "--host", "127.0.0.1", "--port",
                             str(port), "--no-viewer"], cwd=cwd, env=env, stdout=log,
                            stderr=subprocess.STDOUT, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        health = None
        while time.monotonic() < deadline and proc.poll() is None:
            try:
                health = httpx.get(f"http://127.0.0.1:{port}/healthz", timeout=5)
                break
            except httpx.TransportError:
                time.sleep(0.5)
        assert health is not None, (cwd / "serve.log").read_text()
        assert health.status_code == 200 and health.json() == {"status": "ok"}
        page = httpx.get(f"http://127.0.0.1:{port}/", timeout=30)
        assert page.status_code == 200 and "<html" in page.text.lower()
        style = httpx.get(f"http://127.0.0.1:{port}/static/site.css", timeout=30)
        assert style.status_code == 200
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
        log.close()
    # The migrations ran: the database is there, at the newest revision.
    assert (cwd / "data" / "flybo.sqlite").is_file()
    revisions = sorted(p.stem for p in (REPO / "migrations" / "versions").glob("*.py"))
    code = ("import sqlite3, sys; print(sqlite3.connect(sys.argv[1])"
            ".execute('select version_num from alembic_version').fetchone()[0])")
    head = _run([sys.executable, "-c", code, cwd / "data" / "flybo.sqlite"]).stdout.strip()
    assert revisions[-1].startswith(head), (head, revisions)


@pytest.mark.slow
def test_run_from_the_installed_wheel(installed: Path, cwd: Path) -> None:
    out = cwd / "run"
    _run([installed / "flybo", "run", "--area", "maze", "--planner", "classic", "--seed", "0",
          "--seconds", "5", "--out", out, "--quiet"], cwd=cwd, env=_env(cwd),
         timeout=TIMEOUT_S)
    assert out.is_dir() and any(out.iterdir())


PLANNER = '''
import numpy as np

from planners.api import Plan, Planner


class Hover(Planner):
    """Stays where it is; done at the third call."""

    calls = 0

    def plan(self, obs):
        self.calls += 1
        if self.calls >= 3:
            return Plan.finished("done")
        return Plan(np.array([[*obs.pose.position, obs.pose.yaw]]))
'''


@pytest.mark.slow
def test_the_sandbox_runs_from_the_installed_wheel(installed: Path, cwd: Path) -> None:
    planner = cwd / "planner.py"
    planner.write_text(PLANNER)
    checked = _run([installed / "flybo", "planners", "check", planner], cwd=cwd,
                   env=_env(cwd), timeout=TIMEOUT_S)
    assert f"{planner}: passed" in checked.stdout, checked


def _wheel_of(root: Path, name: str, files: dict[str, str]) -> Path:
    """A minimal wheel of distribution `name` 1.0 holding `files`."""
    info = f"{name}-1.0.dist-info"
    files = {**files, f"{info}/METADATA": f"Metadata-Version: 2.1\nName: {name}\nVersion: 1.0\n",
             f"{info}/WHEEL": "Wheel-Version: 1.0\nGenerator: test\nRoot-Is-Purelib: true\n"
                              "Tag: py3-none-any\n"}
    record = []
    for member, text in files.items():
        digest = base64.urlsafe_b64encode(hashlib.sha256(text.encode()).digest())
        record.append(f"{member},sha256={digest.rstrip(b'=').decode()},{len(text.encode())}")
    path = root / f"{name}-1.0-py3-none-any.whl"
    with zipfile.ZipFile(path, "w") as whl:
        for name_in, text in files.items():
            whl.writestr(name_in, text)
        whl.writestr(f"{info}/RECORD", "\n".join([*record, f"{info}/RECORD,,"]) + "\n")
    return path


@pytest.mark.slow
def test_a_clashing_distribution_stops_flybo(tmp_path: Path, wheel: Path, cwd: Path) -> None:
    bin_dir = _fresh_venv(tmp_path / "venv", wheel)
    _run([bin_dir / "flybo", "presets"], cwd=cwd, env=_env(cwd))
    other = _wheel_of(tmp_path, "webtools", {"web/__init__.py": "SOMETHING = 'else'\n",
                                             "web/helpers.py": ""})
    _run([sys.executable, "-m", "pip", "--python", bin_dir / "python", "install", "-q",
          "--no-deps", "--no-index", other])
    result = subprocess.run([bin_dir / "flybo", "presets"], cwd=cwd, env=_env(cwd),
                            capture_output=True, text=True)
    assert result.returncode != 0
    assert "webtools 1.0" in result.stderr and "'web'" in result.stderr, result.stderr


@pytest.mark.slow
def test_a_shadowing_folder_stops_flybo(installed: Path, cwd: Path) -> None:
    # `python -m flybo` puts the working folder first on sys.path.
    (cwd / "server").mkdir()
    (cwd / "server" / "__init__.py").write_text("")
    result = subprocess.run([installed / "python", "-m", "flybo", "presets"], cwd=cwd,
                            env=_env(cwd), capture_output=True, text=True)
    assert result.returncode != 0
    assert f"{cwd / 'server'}" in result.stderr and "no installed distribution" in result.stderr


@pytest.fixture
def fake_site(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """A site-packages folder first on sys.path, holding distribution `demo` with package
    `demo_pkg`."""
    site = tmp_path / "site"
    _unpack(_wheel_of(tmp_path, "demo", {"demo_pkg/__init__.py": "X = 1\n",
                                         "demo_pkg/core.py": "Y = 2\n"}), site)
    monkeypatch.syspath_prepend(str(site))
    yield site
    for name in [m for m in sys.modules if m == "demo_pkg" or m.startswith("demo_pkg.")]:
        del sys.modules[name]


def _unpack(wheel: Path, site: Path) -> None:
    with zipfile.ZipFile(wheel) as whl:
        whl.extractall(site)


def _check(site: Path) -> str | None:
    import importlib

    from flybo import distribution

    importlib.invalidate_caches()
    try:
        distribution.check("demo", ("demo_pkg",))
    except distribution.DistributionClashError as exc:
        return str(exc)
    return None


def test_check_passes_for_the_distribution_s_own_files(fake_site: Path) -> None:
    assert _check(fake_site) is None


def test_check_names_a_distribution_that_wrote_into_the_folder(
    fake_site: Path, tmp_path: Path
) -> None:
    _unpack(_wheel_of(tmp_path, "other", {"demo_pkg/extra.py": ""}), fake_site)
    message = _check(fake_site)
    assert message is not None and "the distribution other 1.0" in message, message


def test_check_names_a_distribution_that_overwrote_a_file(
    fake_site: Path, tmp_path: Path
) -> None:
    _unpack(_wheel_of(tmp_path, "other", {"demo_pkg/__init__.py": "X = 'other'\n"}), fake_site)
    message = _check(fake_site)
    assert message is not None and "other 1.0" in message and "__init__.py" in message, message


def test_check_names_a_shadowing_folder(
    fake_site: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    shadow = tmp_path / "shadow"
    (shadow / "demo_pkg").mkdir(parents=True)
    (shadow / "demo_pkg" / "__init__.py").write_text("")
    monkeypatch.syspath_prepend(str(shadow))
    message = _check(fake_site)
    assert message is not None and str(shadow / "demo_pkg") in message, message
    assert "no installed distribution" in message


def test_python_m_flybo_runs_from_the_checkout() -> None:
    # The checkout's own metadata (flybo.egg-info) is found first from its folder: that is the
    # project, not a clash.
    root = Path(__file__).resolve().parents[1]
    done = subprocess.run([sys.executable, "-m", "flybo", "presets"], cwd=root,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert "default" in done.stdout
