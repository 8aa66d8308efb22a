"""Hostile uploads are refused with a 4xx, quickly and without loading them into memory."""

from __future__ import annotations

import io
import os
import resource
import select
import socket
import struct
import subprocess
import sys
import time
import zipfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient


@pytest.fixture(autouse=True)
def _private_folders(tmp_path: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("FLYBO_DATA_DIR", str(tmp_path / "data"))
    monkeypatch.setenv("FLYBO_CACHE_DIR", str(tmp_path / "cache"))


def _area(client: TestClient, token: str, filename: str, data: bytes | Iterator[bytes],
          **headers: str) -> Any:
    files = {"file": (filename, data if isinstance(data, bytes) else b"")}
    return client.post("/api/v1/areas", headers={"Authorization": f"Bearer {token}",
                                                  **headers},
                       files=files, data={"name": "hostile"})


def _peak_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def test_declared_gigabyte_body_is_refused_before_reading(client: TestClient,
                                                          token: str) -> None:
    started = time.monotonic()
    answer = client.post("/api/v1/areas", headers={"Authorization": f"Bearer {token}",
                                                   "Content-Length": str(1024**3),
                                                   "Content-Type": "multipart/form-data; "
                                                                   "boundary=x"},
                         content=b"--x--\r\n")
    assert answer.status_code == 413 and "too large" in answer.json()["detail"]
    assert time.monotonic() - started < 2


def test_streamed_gigabyte_body_is_cut_off(tmp_path: Path) -> None:
    """Against a real server process: a chunked 1 GB upload is answered 413 long before its
    end, and the server's memory stays flat."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    env = {k: v for k, v in os.environ.items() if not k.startswith("FLYBO_")}
    env["FLYBO_DATA_DIR"] = str(tmp_path / "data")
    token = subprocess.run([sys.executable, "-m", "flybo", "tokens", "create", "--user", "x"],
                           env=env, capture_output=True, text=True, check=True).stdout.strip()
    server = subprocess.Popen([sys.executable, "-m", "flybo", "serve", "--port", str(port),
                               "--workers", "0"], env=env, stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 60
        while True:
            try:
                with socket.create_connection(("127.0.0.1", port), timeout=1):
                    break
            except OSError:
                assert time.monotonic() < deadline
                time.sleep(0.3)
        time.sleep(1.0)
        rss_before = _vm_hwm_mib(server.pid)
        conn = socket.create_connection(("127.0.0.1", port), timeout=30)
        conn.sendall(
            b"POST /api/v1/planners HTTP/1.1\r\nHost: x\r\n"
            + f"Authorization: Bearer {token}\r\n".encode()
            + b"Content-Type: multipart/form-data; boundary=x\r\n"
            + b"Transfer-Encoding: chunked\r\n\r\n")
        part = (b'--x\r\nContent-Disposition: form-data; name="file"; filename="p.py"\r\n'
                b"Content-Type: application/octet-stream\r\n\r\n")
        conn.sendall(f"{len(part):x}\r\n".encode() + part + b"\r\n")
        chunk = b"#" * (1024 * 1024)
        framed = f"{len(chunk):x}\r\n".encode() + chunk + b"\r\n"
        sent = 0
        started = time.monotonic()
        while sent < 1024:
            readable, _, _ = select.select([conn], [], [], 0)
            if readable:
                break
            try:
                conn.sendall(framed)
            except OSError:
                break
            sent += 1
        reply = conn.recv(4096)
        conn.close()
        assert b" 413 " in reply.split(b"\r\n", 1)[0], reply[:200]
        assert sent < 1024 and time.monotonic() - started < 30
        assert _vm_hwm_mib(server.pid) - rss_before < 100
    finally:
        server.terminate()
        server.wait(timeout=30)


def _vm_hwm_mib(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024.0
    raise AssertionError("no VmHWM")


def test_planner_zip_bomb(client: TestClient, token: str) -> None:
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED, compresslevel=9) as archive:
        archive.writestr("planner.py", "from planners.api import Planner\n")
        archive.writestr("zeros.bin.txt", b"\0" * (300 * 1024 * 1024))
    assert len(buffer.getvalue()) < 1024 * 1024
    started = time.monotonic()
    answer = client.post("/api/v1/planners", headers={"Authorization": f"Bearer {token}"},
                         files={"file": ("bomb.zip", buffer.getvalue())},
                         data={"name": "bomb"})
    assert answer.status_code == 422 and "unpacks to" in answer.json()["detail"]
    assert time.monotonic() - started < 5


def test_area_path_traversal_and_wrong_types(client: TestClient, token: str) -> None:
    box = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"
    named = client.post("/api/v1/areas", headers={"Authorization": f"Bearer {token}"},
                        files={"file": ("room.obj", box)}, data={"name": "../../etc"})
    assert named.status_code == 422
    png = _area(client, token, "picture.obj", b"\x89PNG\r\n\x1a\n" + b"\0" * 100)
    assert png.status_code == 422 and "mesh rejected" in png.json()["detail"]
    exe = _area(client, token, "../../room.exe", b"MZ\x90\0")
    assert exe.status_code == 422 and "unsupported" in exe.json()["detail"]


def test_nan_vertices(client: TestClient, token: str) -> None:
    nan = b"v nan 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 3 4\nf 1 2 4\nf 2 3 4\n"
    answer = _area(client, token, "nan.obj", nan)
    assert answer.status_code == 422 and "mesh rejected" in answer.json()["detail"]


def test_ten_million_faces(client: TestClient, token: str) -> None:
    # A binary STL that declares 10 M faces, and an OBJ that holds 10 M face lines.
    stl = b"\0" * 80 + struct.pack("<I", 10_000_000) + b"\0" * 50
    started = time.monotonic()
    declared = _area(client, token, "big.stl", stl)
    assert declared.status_code == 422 and "10000000 faces" in declared.json()["detail"]
    obj = b"v 0 0 0\nv 1 0 0\nv 0 1 0\n" + b"f 1 2 3\n" * 10_000_000
    before = _peak_mib()
    counted = _area(client, token, "big.obj", obj)
    assert counted.status_code == 422 and "10000000 faces" in counted.json()["detail"]
    assert time.monotonic() - started < 30
    assert _peak_mib() - before < 400  # scanned as lines, never parsed into arrays
