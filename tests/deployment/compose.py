"""`docker-compose.yml` rendered as Docker Compose would, and its services as processes here.

Rendering: YAML with its merge keys, `${VAR}` / `${VAR:-default}` / `$$` interpolation from the
`.env` file (`.env.example`, the copy the compose file's header asks for), each service's
environment from its `env_file` and `environment`, the image's `ENV` and `CMD` for services
built from the `Dockerfile`, and `deploy.replicas`. Without a Docker engine the processes run on
this machine; what may change is only where they listen and where named volumes live: a
service's host name and port inside values (`postgres:5432`) become this machine's loopback
address and a free port (`Addresses`).
"""

from __future__ import annotations

import json
import re
import shlex
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

ROOT = Path(__file__).resolve().parents[2]
# Every key a service may use that this renderer understands; another one fails the test, so
# that the compose file cannot grow a setting the tested deployment silently lacks.
KNOWN_KEYS = {"image", "build", "command", "environment", "env_file", "ports", "volumes",
              "depends_on", "healthcheck", "deploy",
              # The planner sandbox's needs from Docker (checked in test_compose.py).
              "cap_add", "cgroup", "security_opt"}
SANDBOX_KEYS = ("cap_add", "cgroup", "security_opt")
_VARIABLE = re.compile(r"\$\$|\$\{([A-Za-z_][A-Za-z0-9_]*)(?::?-([^}]*))?\}|\$([A-Za-z_]\w*)")


def read_env_file(path: Path) -> dict[str, str]:
    """KEY=VALUE lines, as Compose reads an env file (comments and blank lines skipped)."""
    values = {}
    for line in path.read_text().splitlines():
        line = line.strip()
        if line and not line.startswith("#") and "=" in line:
            key, _, value = line.partition("=")
            values[key.strip()] = value.strip().strip('"').strip("'")
    return values


def interpolate(value: Any, variables: dict[str, str]) -> Any:
    """Compose's interpolation of every string in `value`."""
    if isinstance(value, str):
        def one(match: re.Match[str]) -> str:
            if match.group(0) == "$$":
                return "$"
            name = match.group(1) or match.group(3)
            found = variables.get(name)
            if found:
                return found
            return match.group(2) or "" if match.group(1) else ""

        return _VARIABLE.sub(one, value)
    if isinstance(value, list):
        return [interpolate(v, variables) for v in value]
    if isinstance(value, dict):
        return {k: interpolate(v, variables) for k, v in value.items()}
    return value


@dataclass
class Image:
    """What the `Dockerfile` gives a container: environment, entry point and command."""

    env: dict[str, str]
    entrypoint: list[str]
    command: list[str]


def read_dockerfile(path: Path) -> Image:
    env: dict[str, str] = {}
    entrypoint: list[str] = []
    command: list[str] = []
    for line in path.read_text().splitlines():
        word, _, rest = line.strip().partition(" ")
        if word == "ENV":
            env.update(item.split("=", 1) for item in shlex.split(rest))
        elif word == "ENTRYPOINT":
            entrypoint = json.loads(rest)
        elif word == "CMD":
            command = json.loads(rest)
    return Image(env, entrypoint, command)


@dataclass
class Service:
    name: str
    spec: dict[str, Any]
    env: dict[str, str]
    command: list[str]
    replicas: int
    depends_on: dict[str, str] = field(default_factory=dict)

    @property
    def healthcheck(self) -> list[str]:
        test = self.spec.get("healthcheck", {}).get("test", [])
        return [test] if isinstance(test, str) else list(test)

    @property
    def volumes(self) -> list[tuple[str, str]]:
        return [tuple(v.split(":")[:2]) for v in self.spec.get("volumes", [])]  # type: ignore[misc]


def render(compose: Path, env_file: Path, secret_key: str) -> dict[str, Service]:
    """The services of `compose`, with `env_file` as its `.env` (and the secret the compose
    file's header asks the user to set in it)."""
    dotenv = {**read_env_file(env_file), "FLYBO_SECRET_KEY": secret_key}
    raw = yaml.safe_load(compose.read_text())
    image = read_dockerfile(compose.parent / "Dockerfile")
    services = {}
    for name, spec in interpolate(raw["services"], dotenv).items():
        unknown = set(spec) - KNOWN_KEYS
        assert not unknown, (f"service {name} uses {sorted(unknown)}, which the tested "
                             "deployment (tests/deployment) does not start: teach it there")
        env: dict[str, str] = {}
        if "build" in spec:
            env.update(image.env)
        if "env_file" in spec:
            files = spec["env_file"] if isinstance(spec["env_file"], list) else [spec["env_file"]]
            for item in files:
                assert item == ".env", f"service {name}: env file {item} is not the .env"
                env.update(dotenv)
        environment = spec.get("environment", {})
        if isinstance(environment, list):
            environment = dict(item.split("=", 1) for item in environment)
        env.update({k: str(v) for k, v in environment.items()})
        command = spec.get("command", image.command if "build" in spec else [])
        command = shlex.split(command) if isinstance(command, str) else list(command)
        depends = spec.get("depends_on", {})
        if isinstance(depends, list):
            depends = {d: {"condition": "service_started"} for d in depends}
        services[name] = Service(
            name, spec, env, command, int(spec.get("deploy", {}).get("replicas", 1)),
            {d: c.get("condition", "service_started") for d, c in depends.items()})
    return services


def start_order(services: dict[str, Service]) -> list[str]:
    """Services in an order that starts each after what it depends on."""
    order: list[str] = []

    def visit(name: str, seen: tuple[str, ...]) -> None:
        assert name not in seen, f"a dependency cycle: {' -> '.join((*seen, name))}"
        if name in order:
            return
        for dependency in services[name].depends_on:
            visit(dependency, (*seen, name))
        order.append(name)

    for name in services:
        visit(name, ())
    return order


@dataclass
class Addresses:
    """Where each service's container port listens here: (service, port) -> free port."""

    ports: dict[tuple[str, int], int]

    def substitute(self, value: str, inside: str | None = None) -> str:
        """`value` with every `service:port` it names pointed at this machine; in a command
        run `inside` a service's container, its own loopback address too."""
        for (service, port), here in self.ports.items():
            names = [re.escape(service)]
            if service == inside:
                names += [r"127\.0\.0\.1", "localhost"]
            value = re.sub(rf"(?<=[@/])({'|'.join(names)}):{port}\b", f"127.0.0.1:{here}",
                           value)
        return value

    def local(self, service: str, port: int) -> int:
        return self.ports[(service, port)]
