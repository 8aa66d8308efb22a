"""Checks on an uploaded planner: one `.py` file or a `.zip` of pure Python with `planner.py`.

Each refusal raises `PackageError` naming the problem. An accepted upload becomes a normalised
zip (sorted entries, fixed timestamps) whose SHA-256 is the planner version's code hash.

The API checks uploads with these, the workers read stored packages back with them; the dry
run that follows the checks needs the sandbox, so the API is handed one (`PlannerCheck`, see
`server.app.create_app`) rather than importing the workers' code.
"""

from __future__ import annotations

import ast
import hashlib
import io
import stat
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

from pydantic import BaseModel, Field

COMPILED_SUFFIXES = {".pyc", ".pyo", ".so", ".pyd", ".dll", ".dylib", ".o", ".a", ".exe",
                     ".whl", ".egg", ".jar", ".class", ".bin"}


class PackageLimits(BaseModel):
    max_upload_bytes: int = Field(default=1024 * 1024, gt=0)
    max_unpacked_bytes: int = Field(default=10 * 1024 * 1024, gt=0)
    max_files: int = Field(default=200, gt=0)


class PackageError(ValueError):
    """The upload is not an acceptable planner package."""


@dataclass(frozen=True)
class PlannerPackage:
    files: dict[str, bytes]  # relative POSIX path -> content
    zip_bytes: bytes
    code_hash: str

    def extract(self, folder: Path) -> Path:
        """Write the files under `folder` (created), read-only; returns `folder`."""
        folder.mkdir(parents=True, exist_ok=True)
        for name, data in self.files.items():
            target = folder / name
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_bytes(data)
            target.chmod(0o444)
        return folder


@dataclass(frozen=True)
class CheckOutcome:
    """The verdict of an uploaded planner's dry run, with its output for the owner."""

    passed: bool
    output: str
    wall_s: float


class CheckUnavailableError(RuntimeError):
    """The dry run cannot be run: this machine has no sandbox that contains uploaded code.
    The service's failure, not the upload's (HTTP 503)."""


# Runs a checked package's planner for a few simulated seconds in the sandbox
# (`worker.sandbox.dry_run.dry_run` is one); raises `CheckUnavailableError` where it cannot.
PlannerCheck = Callable[[PlannerPackage], CheckOutcome]


def _check_name(name: str) -> str:
    if "\\" in name or name.startswith("/") or (len(name) > 1 and name[1] == ":"):
        raise PackageError(f"absolute or non-POSIX path in the archive: {name!r}")
    path = PurePosixPath(name)
    if ".." in path.parts:
        raise PackageError(f"path leaving the archive ('..') : {name!r}")
    if path.suffix.lower() in COMPILED_SUFFIXES:
        raise PackageError(f"compiled or binary file not allowed: {name!r}")
    return str(path)


def _check_source(name: str, data: bytes) -> None:
    if not name.endswith(".py"):
        return
    try:
        compile(data.decode("utf-8"), name, "exec", dont_inherit=True)
    except UnicodeDecodeError:
        raise PackageError(f"{name} is not UTF-8 text") from None
    except SyntaxError as exc:
        raise PackageError(f"{name} has a syntax error on line {exc.lineno}: {exc.msg}") from None
    except ValueError as exc:  # e.g. null bytes
        raise PackageError(f"{name} is not valid Python source: {exc}") from None


def _check_defines_a_planner(source: bytes) -> None:
    """planner.py must define a class with a base named like `Planner` (checked statically, so
    that files that cannot be planners never reach the sandbox)."""
    tree = ast.parse(source.decode("utf-8"))
    for node in ast.walk(tree):
        if isinstance(node, ast.ClassDef):
            for base in node.bases:
                name = base.attr if isinstance(base, ast.Attribute) else getattr(base, "id", "")
                if "Planner" in name:
                    return
    raise PackageError("planner.py defines no class deriving from planners.api.Planner")


def load_package(filename: str, data: bytes, limits: PackageLimits | None = None) -> PlannerPackage:
    """Check an upload and normalise it."""
    limits = limits or PackageLimits()
    if len(data) > limits.max_upload_bytes:
        raise PackageError(f"upload too large: {len(data)} bytes, at most "
                           f"{limits.max_upload_bytes}")
    suffix = Path(filename).suffix.lower()
    files: dict[str, bytes] = {}
    if suffix == ".py":
        files["planner.py"] = data
    elif suffix == ".zip":
        files = _read_zip(data, limits)
    else:
        raise PackageError(f"unsupported file type {suffix or '(none)'!r}: upload a .py file or "
                           "a .zip with planner.py at its root")
    if "planner.py" not in files:
        raise PackageError("the archive has no planner.py at its root")
    for name, content in files.items():
        _check_source(name, content)
    _check_defines_a_planner(files["planner.py"])
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as out:
        for name in sorted(files):
            info = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
            info.external_attr = 0o444 << 16
            out.writestr(info, files[name])
    digest = hashlib.sha256()
    for name in sorted(files):
        digest.update(name.encode() + b"\0" + hashlib.sha256(files[name]).digest())
    return PlannerPackage(files, buffer.getvalue(), digest.hexdigest())


def _read_zip(data: bytes, limits: PackageLimits) -> dict[str, bytes]:
    try:
        archive = zipfile.ZipFile(io.BytesIO(data))
    except zipfile.BadZipFile:
        raise PackageError("not a valid zip archive") from None
    entries = [i for i in archive.infolist() if not i.is_dir()]
    if len(entries) > limits.max_files:
        raise PackageError(f"too many files: {len(entries)}, at most {limits.max_files}")
    declared = sum(i.file_size for i in entries)
    if declared > limits.max_unpacked_bytes:
        raise PackageError(f"unpacks to {declared} bytes, at most {limits.max_unpacked_bytes}")
    files: dict[str, bytes] = {}
    total = 0
    for info in entries:
        name = _check_name(info.filename)
        mode = info.external_attr >> 16
        if stat.S_ISLNK(mode):
            raise PackageError(f"links are not allowed: {info.filename!r}")
        if info.flag_bits & 0x1:
            raise PackageError(f"encrypted entries are not allowed: {info.filename!r}")
        # Read with a cap: the declared sizes of a hostile archive may lie.
        with archive.open(info) as fh:
            content = fh.read(limits.max_unpacked_bytes - total + 1)
        total += len(content)
        if total > limits.max_unpacked_bytes:
            raise PackageError(f"unpacks to more than {limits.max_unpacked_bytes} bytes")
        if name in files:
            raise PackageError(f"duplicate entry {name!r}")
        files[name] = content
    return files


def read_stored_package(zip_bytes: bytes) -> PlannerPackage:
    """A package from its stored normalised zip (checked again: stores can be tampered with)."""
    return load_package("stored.zip", zip_bytes,
                        PackageLimits(max_upload_bytes=64 * 1024 * 1024,
                                      max_unpacked_bytes=64 * 1024 * 1024, max_files=10_000))
