"""The deployment that is documented is the one that is tested: `docker-compose.yml` itself,
rendered (`tests.deployment.compose`), started as processes on this machine with the same
commands, environment and health checks, in the order its `depends_on` conditions ask; then a
job flies through it and its recording downloads. Only addresses, ports and volume folders are
substituted. A change to the compose file the processes cannot follow fails here.

Two parts of a container have no equivalent on a host and are not run: the image's entry point
(`worker.sandbox.container_init` remounts the container's own cgroups for the sandbox; on a host
it would move the host's processes), and the official images' own entry scripts, replaced by
what they do (PostgreSQL: a cluster with POSTGRES_USER, POSTGRES_PASSWORD and POSTGRES_DB).
"""

from __future__ import annotations

import os
import secrets
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from functools import partial
from pathlib import Path

import httpx
import pytest

from tests.deployment.compose import (
    ROOT,
    SANDBOX_KEYS,
    Addresses,
    Service,
    render,
    start_order,
)

pytestmark = pytest.mark.slow

SERVICES = {"postgres", "redis", "api", "worker"}
CONTAINER_PORTS = {"postgres": 5432, "redis": 6379, "api": 8000}
PG_BIN = Path("/usr/lib/postgresql")
BIN = str(Path(sys.executable).parent)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture(scope="module")
def services() -> dict[str, Service]:
    return render(ROOT / "docker-compose.yml", ROOT / ".env.example", secrets.token_urlsafe(48))


def test_the_compose_file_describes_the_tested_topology(services: dict[str, Service]) -> None:
    assert set(services) == SERVICES
    for service in services.values():
        assert service.healthcheck, f"{service.name} has no health check"
    # Both run planners (the API the uploads' dry runs, the workers the runs): the same
    # sandbox settings (tests/sandbox checks what they allow).
    for key in SANDBOX_KEYS:
        assert services["api"].spec.get(key) == services["worker"].spec.get(key), key
    assert services["worker"].replicas >= 2
    api_env = services["api"].env
    # Scale-out: PostgreSQL and Redis by service name, not the embedded defaults.
    assert api_env["FLYBO_DATABASE_URL"].startswith("postgresql")
    assert "@postgres:5432/" in api_env["FLYBO_DATABASE_URL"]
    assert api_env["FLYBO_BROKER_URL"].startswith("redis://redis:6379")
    assert services["worker"].env == api_env


class Deployment:
    """The rendered services as processes, with their logs and volume folders."""

    def __init__(self, services: dict[str, Service], folder: Path) -> None:
        self.services, self.folder = services, folder
        self.addresses = Addresses({(name, port): _free_port()
                                    for name, port in CONTAINER_PORTS.items()})
        self.procs: list[subprocess.Popen[bytes]] = []

    def volume(self, name: str) -> Path:
        path = self.folder / "volumes" / name
        path.mkdir(parents=True, exist_ok=True)
        return path

    def env(self, service: Service) -> dict[str, str]:
        """The service's environment, pointed at this machine; its mounts' paths in folders."""
        env = {"PATH": f"{BIN}:{os.environ.get('PATH', '/usr/bin:/bin')}",
               "HOME": os.environ.get("HOME", "/root"), "HOSTNAME": socket.gethostname()}
        for key, value in service.env.items():
            value = self.addresses.substitute(value, inside=service.name)
            for source, target in service.volumes:
                local = str(self.volume(source))
                if value == target or value.startswith(target + "/"):
                    value = local + value[len(target):]
                value = value.replace(f"file://{target}/", f"file://{local}/")
            env[key] = value
        return env

    def start(self, service: Service, argv: list[str], env: dict[str, str], n: int = 0,
              user: str | None = None) -> None:
        run_as = [shutil.which("runuser") or "/usr/sbin/runuser", "-u", user, "--"] if user else []
        with (self.folder / f"{service.name}-{n}.log").open("ab") as log:
            self.procs.append(subprocess.Popen([*run_as, *argv], env=env, stdout=log,
                                               stderr=subprocess.STDOUT,
                                               start_new_session=True))

    def healthy(self, service: Service) -> bool:
        """The service's own health check, run as its container would run it."""
        test = service.healthcheck
        env = self.env(service)
        if service.name == "postgres":  # the container's default server is ours
            env.update(PGHOST="127.0.0.1", PGPORT=str(self.addresses.local("postgres", 5432)))
        if test[0] == "CMD-SHELL":
            argv = ["sh", "-c", self.addresses.substitute(test[1], inside=service.name)]
        else:
            assert test[0] == "CMD", test
            argv = [self.addresses.substitute(a, inside=service.name) for a in test[1:]]
            if argv[0] == "redis-cli":  # the container's default port is ours
                argv[1:1] = ["-p", str(self.addresses.local("redis", 6379))]
        done = subprocess.run(argv, env=env, capture_output=True, timeout=60)
        return done.returncode == 0

    def stop(self) -> None:
        for proc in reversed(self.procs):
            proc.terminate()
        for proc in reversed(self.procs):
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def _pg_tool(tool: str) -> str:
    found = sorted(PG_BIN.glob(f"*/bin/{tool}"))
    assert found, f"PostgreSQL's {tool} is missing (apt-get install postgresql)"
    return str(found[-1])


@contextmanager
def _postgres(deployment: Deployment, service: Service) -> Iterator[None]:
    """What the postgres image's entry script does with its environment, then the server."""
    env = service.env
    folder = Path(tempfile.mkdtemp(prefix="flybo-compose-pg-"))  # the postgres user enters it
    try:
        shutil.chown(folder, "postgres", "postgres")
        (folder / "pw").write_text(env["POSTGRES_PASSWORD"])
        shutil.chown(folder / "pw", "postgres", "postgres")
        data = folder / "data"
        subprocess.run(["runuser", "-u", "postgres", "--", _pg_tool("initdb"), "-D", str(data),
                        "-U", env["POSTGRES_USER"], f"--pwfile={folder / 'pw'}",
                        "--auth-local=trust", "--auth-host=scram-sha-256"],
                       check=True, capture_output=True)
        port = deployment.addresses.local("postgres", 5432)
        deployment.start(service, [_pg_tool("postgres"), "-D", str(data), "-p", str(port),
                                   "-c", "listen_addresses=127.0.0.1", "-k", str(folder),
                                   "-c", "fsync=off"], {"PATH": "/usr/bin:/bin"},
                         user="postgres")
        _wait(lambda: subprocess.run([_pg_tool("pg_isready"), "-h", str(folder), "-p",
                                      str(port)], capture_output=True).returncode == 0,
              "the PostgreSQL server", 60)
        subprocess.run(["runuser", "-u", "postgres", "--", _pg_tool("createdb"), "-h",
                        str(folder), "-p", str(port), "-U", env["POSTGRES_USER"],
                        env["POSTGRES_DB"]], check=True, capture_output=True)
        yield
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def _wait(ready: Callable[[], bool], what: str, timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while not ready():
        assert time.monotonic() < deadline, f"{what} was not ready within {timeout_s:g} s"
        time.sleep(1.0)


def _start_service(stack: ExitStack, deployment: Deployment, service: Service) -> None:
    image = str(service.spec.get("image", ""))
    if image.startswith("postgres:"):
        stack.enter_context(_postgres(deployment, service))
    elif image.startswith("redis:"):
        volume = deployment.volume(service.volumes[0][0])
        port = deployment.addresses.local("redis", 6379)
        deployment.start(service, [*service.command, "--port", str(port), "--bind",
                                   "127.0.0.1", "--dir", str(volume)], deployment.env(service))
    else:
        assert "build" in service.spec, f"{service.name}: neither an image known here nor built"
        argv = [deployment.addresses.substitute(a, inside=service.name)
                for a in service.command]
        # Where it listens: this machine's loopback address and the port given to its own.
        port = CONTAINER_PORTS.get(service.name)
        argv = ["127.0.0.1" if a == "0.0.0.0" else
                str(deployment.addresses.local(service.name, port))
                if port is not None and a == str(port) else a for a in argv]
        for n in range(service.replicas):
            deployment.start(service, argv, deployment.env(service), n)


def _seed_cache(deployment: Deployment, service: Service, area: str) -> None:
    """The built ground truth of `area` copied into the workers' cache volume, as a volume
    kept from an earlier start would hold it (building it takes a minute)."""
    cache = Path(deployment.env(service)["FLYBO_CACHE_DIR"]) / "ground_truth"
    source = Path(os.environ.get("FLYBO_CACHE_DIR", Path.home() / ".cache" / "flybo"))
    for path in (source / "ground_truth").glob(f"{area}-*.npz"):
        cache.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(path, cache / path.name)


def test_the_compose_deployment_runs_a_job(services: dict[str, Service], tmp_path: Path) -> None:
    deployment = Deployment(services, tmp_path)
    _seed_cache(deployment, services["worker"], "maze")
    with ExitStack() as stack:
        stack.callback(deployment.stop)
        for name in start_order(services):
            service = services[name]
            for dependency, condition in service.depends_on.items():
                if condition == "service_healthy":
                    _wait(partial(deployment.healthy, services[dependency]),
                          f"{dependency} (health check)", 300)
            _start_service(stack, deployment, service)
        for name in start_order(services):
            _wait(partial(deployment.healthy, services[name]), f"{name} (health check)", 300)
        api = services["api"]
        # As the compose file's header says: `docker compose exec api flybo tokens create`.
        token = subprocess.run(["flybo", "tokens", "create", "--user", "compose"],
                               env=deployment.env(api), capture_output=True, text=True,
                               check=True).stdout.strip()
        base = f"http://127.0.0.1:{deployment.addresses.local('api', 8000)}"
        _job_flies(base, token)
    log = (tmp_path / "api-0.log").read_text(errors="replace")
    # Production with Redis: one API process per usable core.
    assert f"{len(os.sched_getaffinity(0))} API process(es)" in log


def _job_flies(base: str, token: str) -> None:
    job = httpx.post(f"{base}/api/v1/jobs", headers={"Authorization": f"Bearer {token}"},
                     json={"planner": "classic", "areas": ["maze"], "runs": 2, "seconds": 20},
                     timeout=120)
    assert job.status_code == 201, job.text
    deadline = time.monotonic() + 600
    while True:
        polled = httpx.get(f"{base}/api/v1/jobs/{job.json()['id']}", timeout=30).json()
        if polled["status"] in ("succeeded", "failed", "cancelled"):
            break
        assert time.monotonic() < deadline, polled
        time.sleep(2)
    assert polled["status"] == "succeeded", polled
    run_id = polled["runs"][0]["id"]
    recording = httpx.get(f"{base}/api/v1/runs/{run_id}/artifacts/recording", timeout=60)
    assert recording.status_code == 200 and len(recording.content) > 1000
