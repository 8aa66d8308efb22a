"""The servers of the server host, each started in its namespace on the host's own address: a
PostgreSQL cluster of its own (initdb), a Redis server, moto's S3-compatible server as the
artifact store, and the API (`flybo serve --workers 0`)."""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import httpx

from tests.multihost.netns import Host

PG_BIN = Path("/usr/lib/postgresql")
PG_PORT, REDIS_PORT, S3_PORT, API_PORT = 5432, 6379, 9000, 8000
BUCKET = "flybo-artifacts"
# moto accepts any credentials; boto3 wants some.
S3_CREDENTIALS = {"AWS_ACCESS_KEY_ID": "flybo-test", "AWS_SECRET_ACCESS_KEY": "flybo-test",
                  "AWS_DEFAULT_REGION": "us-east-1"}


def wait_until(ready: Callable[[], bool], what: str, timeout_s: float = 90.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not ready():
        if time.monotonic() > deadline:
            raise AssertionError(f"{what} did not come up within {timeout_s:g} s")
        time.sleep(0.3)


def port_open(address: str, port: int) -> bool:
    try:
        with socket.create_connection((address, port), timeout=1):
            return True
    except OSError:
        return False


def pg_tool(tool: str) -> str:
    found = sorted(PG_BIN.glob(f"*/bin/{tool}"))
    if not found:
        raise AssertionError(f"PostgreSQL's {tool} is missing under {PG_BIN} (apt-get install "
                             "postgresql)")
    return str(found[-1])


@contextmanager
def postgres(host: Host, logs: Path) -> Iterator[str]:
    """A fresh cluster listening on the host's address; yields its SQLAlchemy URL."""
    # A folder the postgres user may enter (pytest's are private to root).
    folder = Path(tempfile.mkdtemp(prefix="flybo-multihost-pg-"))
    try:
        shutil.chown(folder, "postgres", "postgres")
        data = folder / "data"
        subprocess.run(["runuser", "-u", "postgres", "--", pg_tool("initdb"), "-D", str(data),
                        "--auth=trust", "-U", "postgres"], check=True, capture_output=True)
        with (data / "pg_hba.conf").open("a") as hba:
            hba.write(f"host all all {host.address.rsplit('.', 1)[0]}.0/24 trust\n")
        env = {"PATH": os.environ.get("PATH", "/usr/bin:/bin")}
        host.start([pg_tool("postgres"), "-D", str(data), "-c",
                    f"listen_addresses={host.address}", "-p", str(PG_PORT), "-k", str(folder),
                    "-c", "fsync=off"], env, logs / "postgres.log", user="postgres")
        wait_until(lambda: port_open(host.address, PG_PORT), "PostgreSQL")
        yield f"postgresql+psycopg://postgres@{host.address}:{PG_PORT}/postgres"
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def redis_server(host: Host, logs: Path) -> str:
    # Reached from the other hosts: not in protected mode, which answers only loopback.
    host.start(["redis-server", "--bind", host.address, "--port", str(REDIS_PORT), "--save", "",
                "--appendonly", "no", "--protected-mode", "no"],
               {"PATH": os.environ.get("PATH", "")}, logs / "redis.log")
    wait_until(lambda: port_open(host.address, REDIS_PORT), "Redis")
    return f"redis://{host.address}:{REDIS_PORT}/0"


def s3_server(host: Host, logs: Path) -> str:
    """moto's S3-compatible server with the artifacts' bucket; yields its endpoint URL."""
    env = {**os.environ, **S3_CREDENTIALS}
    host.start([sys.executable, "-m", "moto.server", "-H", host.address, "-p", str(S3_PORT)],
               env, logs / "s3.log")
    endpoint = f"http://{host.address}:{S3_PORT}"
    wait_until(lambda: port_open(host.address, S3_PORT), "the S3 server")
    import boto3

    boto3.client("s3", endpoint_url=endpoint, **_boto_credentials()).create_bucket(
        Bucket=BUCKET)
    return endpoint


def _boto_credentials() -> dict[str, str]:
    return {"aws_access_key_id": S3_CREDENTIALS["AWS_ACCESS_KEY_ID"],
            "aws_secret_access_key": S3_CREDENTIALS["AWS_SECRET_ACCESS_KEY"],
            "region_name": S3_CREDENTIALS["AWS_DEFAULT_REGION"]}


def service_env(folder: Path, **settings: str) -> dict[str, str]:
    """The environment of a flybo process with folders of its own under `folder` (no folder
    is shared between hosts) and the given FLYBO_* settings."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(("FLYBO_", "AWS_"))}
    env.update(S3_CREDENTIALS)
    env["FLYBO_DATA_DIR"] = str(folder / "data")
    env["FLYBO_CACHE_DIR"] = str(folder / "cache")
    env.update({f"FLYBO_{k.upper()}": v for k, v in settings.items()})
    return env


def seed_area_cache(folder: Path, area: str) -> None:
    """Copy (never share) this machine's built ground truth of `area` into a host's cache, so
    that a worker host does not spend a minute building it."""
    source = Path(os.environ.get("FLYBO_CACHE_DIR", Path.home() / ".cache" / "flybo"))
    for path in (source / "ground_truth").glob(f"{area}-*.npz"):
        target = folder / "cache" / "ground_truth" / path.name
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(path, target)


def api(host: Host, env: dict[str, str], logs: Path) -> str:
    host.start([sys.executable, "-m", "flybo", "serve", "--host", host.address, "--port",
                str(API_PORT), "--workers", "0", "--no-viewer"], env, logs / "api.log")
    base = f"http://{host.address}:{API_PORT}"

    def healthy() -> bool:
        try:
            return httpx.get(f"{base}/healthz", timeout=2).status_code == 200
        except httpx.HTTPError:
            return False

    wait_until(healthy, "the API", timeout_s=180)
    return base
