"""Hostile uploads against the static checks (`server.planner_package`): the API's process never
compiles uploaded source, the subprocess that does has CPU and memory limits, and every refusal
is a `PackageError` (HTTP 422), never a crash."""

from __future__ import annotations

import ast
import builtins
import io
import re
import resource
import time
import zipfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from server.app import create_app as create_api
from server.db import make_engine, make_session_factory, session_scope
from server.migrate import upgrade
from server.planner_package import PackageError, PackageLimits, load_package
from server.security import create_token
from server.settings import Settings

GOOD = b"from planners.api import Planner\n\n\nclass Hover(Planner):\n    pass\n"


def _zip(entries: dict[str, bytes]) -> bytes:
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
        for name, data in entries.items():
            archive.writestr(name, data)
    return buffer.getvalue()


def _cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def test_a_ten_mib_planner_in_a_ten_kb_zip_is_refused_at_once() -> None:
    # This took 46 s of CPU time and 6.4 GB in the API's process.
    source = GOOD + b"x = 1\n" * ((10 * 1024 * 1024 - len(GOOD)) // 6)
    bomb = _zip({"planner.py": source})
    assert len(bomb) < 20_000 and len(source) <= 10 * 1024 * 1024
    before, started = _cpu(), time.monotonic()
    with pytest.raises(PackageError, match=r"planner\.py is \d+ bytes of source, at most 262144"):
        load_package("bomb.zip", bomb)
    assert _cpu() - before < 0.5 and time.monotonic() - started < 2


def test_many_files_each_under_the_cap_are_refused_by_the_total() -> None:
    files = {f"m{i}.py": b"x = [" + b"1, " * 80_000 + b"]\n" for i in range(8)}
    with pytest.raises(PackageError, match=r"\.py files hold \d+ bytes of source, at most 1048576"):
        load_package("many.zip", _zip({"planner.py": GOOD, **files}))


def test_this_process_never_compiles_uploaded_source(monkeypatch: pytest.MonkeyPatch) -> None:
    def refuse(*args: Any, **kwargs: Any) -> Any:
        raise AssertionError("uploaded source compiled in the API's process")

    monkeypatch.setattr(builtins, "compile", refuse)
    monkeypatch.setattr(ast, "parse", refuse)
    package = load_package("planner.py", GOOD)
    assert set(package.files) == {"planner.py"}
    with pytest.raises(PackageError, match="syntax error on line 1"):
        load_package("planner.py", b"def broken(:\n")


def test_compiling_is_cut_off_at_its_cpu_limit() -> None:
    limits = PackageLimits(max_source_bytes=8 << 20, max_total_source_bytes=8 << 20,
                           check_cpu_seconds=1, check_memory_bytes=4 << 30)
    source = GOOD + b"x = 1\n" * ((6 << 20) // 6)
    before = _cpu()
    with pytest.raises(PackageError, match="took more than 1 s of CPU time"):
        load_package("planner.py", source, limits.model_copy(
            update={"max_upload_bytes": 8 << 20}))
    assert _cpu() - before < 1.0  # spent in the subprocess, not here


def test_compiling_is_cut_off_at_its_memory_limit() -> None:
    limits = PackageLimits(max_upload_bytes=2 << 20, max_source_bytes=2 << 20,
                           max_total_source_bytes=2 << 20, check_memory_bytes=96 << 20)
    source = GOOD + b"x = [" + b"1, " * (500_000) + b"]\n"
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    with pytest.raises(PackageError, match=r"too large|complex"):
        load_package("planner.py", source, limits)
    assert resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - peak < 100_000  # KiB


@pytest.mark.parametrize(("source", "needle"), [
    (GOOD + b"x = " + b"1 + " * 50_000 + b"1\n", "too large or too deeply nested"),
    (GOOD + b"x = " + b"(" * 5000 + b")" * 5000 + b"\n", "syntax error"),
    (b"x = '\0'\n", "not valid Python source|syntax error"),
    (b"\xff\xfe", "not UTF-8"),
    (b"x = 1\n", "defines no class deriving from"),
])
def test_hostile_source_is_refused_with_a_reason(source: bytes, needle: str) -> None:
    with pytest.raises(PackageError, match=needle):
        load_package("planner.py", source)


def test_stored_packages_are_checked_the_same_way() -> None:
    from server.planner_package import read_stored_package

    package = load_package("code.zip", _zip({"planner.py": GOOD, "util.py": b"y = 2\n"}))
    again = read_stored_package(package.zip_bytes)
    assert again.code_hash == package.code_hash
    with pytest.raises(PackageError, match="syntax error"):
        read_stored_package(_zip({"planner.py": GOOD, "util.py": b"def (:\n"}))


# -- through the API ----------------------------------------------------------------------------

@pytest.fixture
def api(tmp_path: Path) -> Iterator[tuple[TestClient, dict[str, str]]]:
    """The API alone (no dry run: the static checks answer first)."""
    settings = Settings(data_dir=tmp_path / "data",
                        database_url=f"sqlite:///{tmp_path / 'flybo.sqlite'}")
    engine = make_engine(settings.db_url)
    upgrade(engine)
    with session_scope(make_session_factory(engine)) as session:
        token = create_token(session, "alice", settings.secret_key)
    with TestClient(create_api(settings, sweeper=False, sync_areas=False)) as client:
        yield client, {"Authorization": f"Bearer {token}"}
    engine.dispose()


def _upload(api: tuple[TestClient, dict[str, str]], filename: str, data: bytes) -> Any:
    client, headers = api
    return client.post("/api/v1/planners", headers=headers,
                       files={"file": (filename, io.BytesIO(data))}, data={"name": "hostile"})


@pytest.mark.parametrize(("filename", "data", "needle"), [
    ("bomb.zip", _zip({"planner.py": GOOD + b"x = 1\n" * (1 << 20)}), "bytes of source"),
    ("planner.py", GOOD + b"x = " + b"1 + " * 50_000 + b"1\n", "too deeply nested"),
])
def test_the_api_refuses_them_with_422(api: tuple[TestClient, dict[str, str]], filename: str,
                                       data: bytes, needle: str) -> None:
    response = _upload(api, filename, data)
    assert response.status_code == 422, response.text
    assert needle in response.json()["detail"]


# -- names and content of archive entries -------------------------------------------------------

def _raw_zip(names: list[str], data: bytes = b"x = 1\n") -> bytes:
    """A zip whose entries have exactly `names` (written as raw as zipfile allows: a NUL is
    put back into the stored name after writing)."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        archive.writestr("planner.py", GOOD)
        for name in names:
            archive.writestr(name.replace("\0", "\x01"), b"" if name.endswith("/") else data)
    raw = buffer.getvalue()
    for name in names:
        if "\0" in name:
            raw = raw.replace(name.replace("\0", "\x01").encode(), name.encode())
    return raw


@pytest.mark.parametrize(("names", "needle"), [
    (["planner.py\0.txt"], "NUL character"),
    (["util\0/evil.py"], "NUL character"),
    (["bell\a.py"], "control character"),
    (["new\nline.py"], "control character"),
    (["."], "'.' part"),
    (["./util.py"], "'.' part"),
    (["lib/./util.py"], "'.' part"),
    (["lib//util.py"], "empty or '.' part"),
    (["lib", "lib/util.py"], "'lib' is both a file and a folder"),
    (["lib/util.py", "lib"], "'lib' is both a file and a folder"),
    (["a/b/c.py", "a/b"], "'a/b' is both a file and a folder"),
    (["lib/", "lib"], "'lib' is both a file and a folder"),
    ([("x" * 256) + ".py"], "name too long"),
    (["/".join(["d" * 200] * 6) + "/u.py"], "name too long"),
    (["..\\evil.py"], "non-POSIX"),
    (["lib/../../evil.py"], "'..'"),
])
def test_archive_names_are_checked_as_stored(names: list[str], needle: str) -> None:
    with pytest.raises(PackageError, match=re.escape(needle)):
        load_package("code.zip", _raw_zip(names))


def test_plain_folders_and_unicode_names_are_fine(tmp_path: Path) -> None:
    package = load_package("code.zip", _raw_zip(["lib/", "lib/util.py", "données/notes.md"]))
    assert set(package.files) == {"planner.py", "lib/util.py", "données/notes.md"}
    package.extract(tmp_path / "code")
    assert (tmp_path / "code" / "lib" / "util.py").read_bytes() == b"x = 1\n"


ELF = b"\x7fELF\x02\x01\x01" + b"\0" * 57
PE = b"MZ" + b"\0" * 58 + (64).to_bytes(4, "little") + b"PE\0\0" + b"\0" * 20


@pytest.mark.parametrize(("name", "data", "kind"), [
    ("notes.txt", ELF, "an ELF executable or library"),
    ("data/weights.npy", ELF, "an ELF executable or library"),
    ("helper.dat", PE, "a Windows executable"),
    ("README", b"\xcf\xfa\xed\xfe" + b"\0" * 28, "a Mach-O binary"),
    ("table.csv", b"\xa7\r\r\n" + b"\0" * 28, "compiled Python bytecode"),
    ("vendor.txt", _zip({"m.py": b"x = 1"}), "a zip archive"),
    ("blob.txt", b"\x1f\x8b\x08\x00" + b"\0" * 16, "a gzip archive"),
])
def test_binary_content_is_found_by_content(name: str, data: bytes, kind: str) -> None:
    with pytest.raises(PackageError, match=f"{re.escape(repr(name))} is {re.escape(kind)}"):
        load_package("code.zip", _zip({"planner.py": GOOD, name: data}))


def test_text_and_plain_data_files_pass() -> None:
    files = {"README.md": b"# MZ and BZh and PK are fine in text\r\n",
             "table.csv": b"ab\r\ncd\r\n", "grid.npy": b"\x93NUMPY\x01\x00" + b"\0" * 100}
    package = load_package("code.zip", _zip({"planner.py": GOOD, **files}))
    assert set(package.files) == {"planner.py", *files}


def test_a_corrupt_entry_is_refused_not_a_crash() -> None:
    raw = bytearray(_zip({"planner.py": GOOD, "util.py": b"y = 2\n" * 1000}))
    at = raw.find(b"util.py") + len(b"util.py") + 5  # inside the deflated data
    raw[at:at + 8] = b"\xff" * 8
    with pytest.raises(PackageError):
        load_package("code.zip", bytes(raw))


@pytest.mark.parametrize("names", [["lib", "lib/util.py"], ["x" * 300 + ".py"],
                                   ["planner.py\0.sh"], ["."]])
def test_the_api_refuses_bad_names_with_422(api: tuple[TestClient, dict[str, str]],
                                           names: list[str]) -> None:
    response = _upload(api, "code.zip", _raw_zip(names))
    assert response.status_code == 422, response.text


# -- what the planner process reports ----------------------------------------------------------

def test_only_known_timing_keys_are_kept() -> None:
    from worker.sandbox.protocol import clean_timing

    hostile = {"map": 1.5, "plan": 2, "extra": 3.0, "planner_ms": 9.0, **{str(i): i for i in
                                                                           range(1000)}}
    assert clean_timing(hostile) == {"map": 1.5, "plan": 2.0}
    assert clean_timing({"map": True, "plan": -1.0}) == {}
    assert clean_timing({"map": float("nan"), "plan": float("inf")}) == {}
    assert clean_timing({"map": "1", "plan": [1]}) == {}
    assert clean_timing(["map", 1]) == {} and clean_timing(None) == {}
