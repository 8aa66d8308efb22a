"""Checks on an uploaded planner: one `.py` file or a `.zip` of pure Python with `planner.py`.

Each refusal raises `PackageError` naming the problem. An accepted upload becomes a normalised
zip (sorted entries, fixed timestamps) whose SHA-256 is the planner version's code hash.

Compiling hostile source can take a long time and much memory (a 10 KB zip unpacks to 10 MiB of
Python), so each `.py` file is capped at `PackageLimits.max_source_bytes`, and the compiling and
parsing happen in a subprocess of this interpreter with CPU-time and memory limits
(`check_sources`), never in the API's own process.

The API checks uploads with these, the workers read stored packages back with them; the dry
run that follows the checks needs the sandbox, so the API is handed one (`PlannerCheck`, see
`server.app.create_app`) rather than importing the workers' code.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import stat
import subprocess
import sys
import threading
import zipfile
import zlib
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

from pydantic import BaseModel, Field

COMPILED_SUFFIXES = {".pyc", ".pyo", ".so", ".pyd", ".dll", ".dylib", ".o", ".a", ".exe",
                     ".whl", ".egg", ".jar", ".class", ".bin"}


class PackageLimits(BaseModel):
    max_upload_bytes: int = Field(default=1024 * 1024, gt=0)
    max_unpacked_bytes: int = Field(default=10 * 1024 * 1024, gt=0)
    max_files: int = Field(default=200, gt=0)
    # Ten times the project's largest module; compiling one this size takes about half a second
    # of CPU time, all of them about two seconds.
    max_source_bytes: int = Field(default=256 * 1024, gt=0, description="per .py file")
    max_total_source_bytes: int = Field(default=1024 * 1024, gt=0, description="all .py files")
    # The subprocess that compiles and parses the sources.
    check_cpu_seconds: int = Field(default=5, ge=1)
    check_memory_bytes: int = Field(default=1024 * 1024 * 1024, ge=64 * 1024 * 1024)
    check_wall_seconds: float = Field(default=30.0, gt=0)


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


class SandboxPolicyError(RuntimeError):
    """The sandbox settings are not allowed in this environment (the insecure fallback in
    production): the service does not start, and uploaded code does not run."""


# What a refused upload is told to wait: about one dry run of a simple planner.
CHECKS_RETRY_AFTER_S = 15


class ChecksBusyError(RuntimeError):
    """As many uploads as allowed are being checked in this process (HTTP 429)."""


class CheckSlots:
    """At most `limit` uploads checked at once, counted across the threads of this process."""

    def __init__(self, limit: int) -> None:
        self.limit = limit
        self._free = threading.BoundedSemaphore(limit)

    @contextmanager
    def taken(self) -> Iterator[None]:
        """Hold a slot for the block; `ChecksBusyError` at once (no waiting) when none is
        free, so that a burst of uploads cannot pile up threads in the API."""
        if not self._free.acquire(blocking=False):
            raise ChecksBusyError(
                f"{self.limit} uploaded planners are being checked right now, the most this "
                f"server checks at once; nothing was stored, try again in "
                f"{CHECKS_RETRY_AFTER_S} s")
        try:
            yield
        finally:
            self._free.release()


MAX_NAME_PART_BYTES = 255  # a file or folder name, as file systems allow
MAX_NAME_BYTES = 1024  # a whole path in the archive


def _check_name(raw: str) -> str:
    """The archive entry's name as stored (`ZipInfo.orig_filename`: `filename` drops what
    follows a NUL), checked; returns it normalised (no trailing '/')."""
    shown = repr(raw[:80] + ("..." if len(raw) > 80 else ""))
    if "\0" in raw:
        raise PackageError(f"NUL character in an archive name: {shown}")
    if any(ord(c) < 32 or 127 <= ord(c) < 160 for c in raw):
        raise PackageError(f"control character in an archive name: {shown}")
    if "\\" in raw or raw.startswith("/") or (len(raw) > 1 and raw[1] == ":"):
        raise PackageError(f"absolute or non-POSIX path in the archive: {shown}")
    parts = raw.removesuffix("/").split("/")
    if ".." in parts:
        raise PackageError(f"path leaving the archive ('..') : {shown}")
    if any(part in ("", ".") for part in parts):
        raise PackageError(f"empty or '.' part in an archive name: {shown}")
    if (len(raw.encode()) > MAX_NAME_BYTES
            or any(len(part.encode()) > MAX_NAME_PART_BYTES for part in parts)):
        raise PackageError(f"name too long in the archive (at most {MAX_NAME_PART_BYTES} bytes "
                           f"a part, {MAX_NAME_BYTES} in all): {shown}")
    name = "/".join(parts)
    if PurePosixPath(name).suffix.lower() in COMPILED_SUFFIXES:
        raise PackageError(f"compiled or binary file not allowed: {name!r}")
    return name


# Executables, libraries, bytecode and archives, by their first bytes, whatever their name.
_MAGIC = (
    (b"\x7fELF", "an ELF executable or library"),
    (b"\xfe\xed\xfa\xce", "a Mach-O binary"), (b"\xfe\xed\xfa\xcf", "a Mach-O binary"),
    (b"\xce\xfa\xed\xfe", "a Mach-O binary"), (b"\xcf\xfa\xed\xfe", "a Mach-O binary"),
    (b"\xca\xfe\xba\xbe", "a Mach-O or Java class file"),
    (b"!<arch>\n", "a static library"),
    (b"PK\x03\x04", "a zip archive (wheel, egg, jar)"), (b"PK\x05\x06", "a zip archive"),
    (b"\x00asm", "a WebAssembly module"),
    (b"\x1f\x8b", "a gzip archive"), (b"\xfd7zXZ\x00", "an xz archive"),
)


def _binary_kind(data: bytes) -> str | None:
    """What executable or compiled content `data` is, or None."""
    for magic, kind in _MAGIC:
        if data.startswith(magic):
            return kind
    if data[:3] == b"BZh" and data[4:10] == b"1AY&SY":
        return "a bzip2 archive"
    if data[:2] == b"MZ" and len(data) >= 64:
        offset = int.from_bytes(data[0x3C:0x40], "little")
        if data[offset:offset + 4] == b"PE\0\0":
            return "a Windows executable or library"
    # Python bytecode: a 16-bit magic number of CPython 3 (3000 to 3999), then b"\r\n".
    version = int.from_bytes(data[:2], "little")
    if len(data) >= 16 and data[2:4] == b"\r\n" and 3000 <= version < 4000:
        return "compiled Python bytecode"
    return None


# Run by `check_sources` as `python -I -S -c _CHECKER CPU_SECONDS MEMORY_BYTES`, the sources as
# JSON on stdin; prints {"error": null} or {"error": "why"}. The standard library only.
_CHECKER = r"""
import ast, json, resource, sys

cpu, memory = int(sys.argv[1]), int(sys.argv[2])
resource.setrlimit(resource.RLIMIT_CPU, (cpu, cpu + 1))
resource.setrlimit(resource.RLIMIT_AS, (memory, memory))
resource.setrlimit(resource.RLIMIT_CORE, (0, 0))


def problem(name, text):
    try:
        compile(text, name, "exec", dont_inherit=True)
    except SyntaxError as exc:
        return f"{name} has a syntax error on line {exc.lineno}: {exc.msg}"
    except ValueError as exc:  # e.g. null bytes
        return f"{name} is not valid Python source: {exc}"
    except (MemoryError, RecursionError):
        return f"{name} is too large or too deeply nested to compile"
    return None


def defines_a_planner(text):
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, ast.ClassDef):
            for base in node.bases:
                name = base.attr if isinstance(base, ast.Attribute) else getattr(base, "id", "")
                if "Planner" in name:
                    return True
    return False


files = json.load(sys.stdin)
error = None
for name, text in files.items():
    error = problem(name, text)
    if error:
        break
if error is None:
    try:
        if not defines_a_planner(files["planner.py"]):
            error = "planner.py defines no class deriving from planners.api.Planner"
    except (MemoryError, RecursionError):
        error = "planner.py is too large or too deeply nested to compile"
print(json.dumps({"error": error}))
"""


def _decode_source(name: str, data: bytes, limits: PackageLimits) -> str:
    if len(data) > limits.max_source_bytes:
        raise PackageError(f"{name} is {len(data)} bytes of source, at most "
                           f"{limits.max_source_bytes} per file")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise PackageError(f"{name} is not UTF-8 text") from None


def check_sources(files: dict[str, bytes], limits: PackageLimits) -> None:
    """Every `.py` file compiles, and planner.py defines a class with a base named like
    `Planner` (checked statically, so that files that cannot be planners never reach the
    sandbox). Compiled in a subprocess with `limits.check_cpu_seconds` of CPU time and
    `limits.check_memory_bytes` of address space."""
    sources = {name: _decode_source(name, data, limits) for name, data in files.items()
               if name.endswith(".py")}
    total = sum(len(files[name]) for name in sources)
    if total > limits.max_total_source_bytes:
        raise PackageError(f"the .py files hold {total} bytes of source, at most "
                           f"{limits.max_total_source_bytes}")
    env = {key: os.environ[key] for key in ("PATH", "LD_LIBRARY_PATH", "LANG")
           if key in os.environ}
    try:
        done = subprocess.run(
            [sys.executable, "-I", "-S", "-B", "-c", _CHECKER, str(limits.check_cpu_seconds),
             str(limits.check_memory_bytes)],
            input=json.dumps(sources).encode(), capture_output=True, env=env,
            timeout=limits.check_wall_seconds)
    except subprocess.TimeoutExpired:
        raise PackageError(f"checking the Python sources took more than "
                           f"{limits.check_wall_seconds:g} s") from None
    if done.returncode != 0:
        if done.returncode in (-24, -9):  # SIGXCPU, or SIGKILL past the hard limit
            raise PackageError(f"checking the Python sources took more than "
                               f"{limits.check_cpu_seconds} s of CPU time")
        raise PackageError("the Python sources are too large or complex to check "
                           f"(the check ended with code {done.returncode})")
    try:
        error = json.loads(done.stdout)["error"]
    except (ValueError, KeyError, TypeError):
        raise PackageError("the Python sources could not be checked") from None
    if error is not None:
        raise PackageError(str(error))


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
    check_sources(files, limits)
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
    except (zipfile.BadZipFile, zipfile.LargeZipFile, ValueError, EOFError):
        raise PackageError("not a valid zip archive") from None
    infos = archive.infolist()
    count = sum(not info.orig_filename.endswith("/") for info in infos)
    if count > limits.max_files or len(infos) > 2 * limits.max_files:
        raise PackageError(f"too many files: {count} and {len(infos) - count} folders, at most "
                           f"{limits.max_files} files")
    named = [(_check_name(info.orig_filename), info) for info in infos]
    folders = {name for name, info in named if info.orig_filename.endswith("/")}
    entries = [(name, info) for name, info in named if not info.orig_filename.endswith("/")]
    declared = sum(i.file_size for _, i in entries)
    if declared > limits.max_unpacked_bytes:
        raise PackageError(f"unpacks to {declared} bytes, at most {limits.max_unpacked_bytes}")
    files: dict[str, bytes] = {}
    total = 0
    for name, info in entries:
        mode = info.external_attr >> 16
        if stat.S_ISLNK(mode):
            raise PackageError(f"links are not allowed: {name!r}")
        if info.flag_bits & 0x1:
            raise PackageError(f"encrypted entries are not allowed: {name!r}")
        if name in files:
            raise PackageError(f"duplicate entry {name!r}")
        # Read with a cap: the declared sizes of a hostile archive may lie.
        try:
            with archive.open(info) as fh:
                content = fh.read(limits.max_unpacked_bytes - total + 1)
        except (zipfile.BadZipFile, NotImplementedError, RuntimeError, ValueError, EOFError,
                OSError, zlib.error) as exc:
            raise PackageError(f"cannot read {name!r} from the archive: {exc}") from None
        total += len(content)
        if total > limits.max_unpacked_bytes:
            raise PackageError(f"unpacks to more than {limits.max_unpacked_bytes} bytes")
        kind = _binary_kind(content)
        if kind is not None:
            raise PackageError(f"compiled or binary file not allowed: {name!r} is {kind}")
        files[name] = content
    # A file where another entry needs a folder of that name could not be unpacked.
    for name in files:
        folders.update(str(p) for p in PurePosixPath(name).parents if str(p) != ".")
    clash = sorted(folders & set(files))
    if clash:
        raise PackageError(f"{clash[0]!r} is both a file and a folder in the archive")
    return files


def read_stored_package(zip_bytes: bytes) -> PlannerPackage:
    """A package from its stored normalised zip (checked again: stores can be tampered with)."""
    # Limits as wide as any upload's ever were; the check's CPU and memory limits still hold.
    return load_package("stored.zip", zip_bytes,
                        PackageLimits(max_upload_bytes=64 * 1024 * 1024,
                                      max_unpacked_bytes=64 * 1024 * 1024, max_files=10_000,
                                      max_source_bytes=64 * 1024 * 1024,
                                      max_total_source_bytes=64 * 1024 * 1024))
