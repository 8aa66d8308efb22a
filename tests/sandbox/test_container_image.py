"""The production image isolates uploaded planners: its container, as `Dockerfile` and
`docker-compose.yml` describe it, reproduced with podman (`container_settings`), finds full
isolation and contains hostile planners; without the settings the compose file grants, uploads
are refused. A change to either file that breaks the sandbox fails here."""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import sys
from functools import cache
from pathlib import Path
from typing import Any

import pytest

from tests.sandbox import container_settings as image
from tests.sandbox.conftest import required

SECRET = "canary-secret-" + "x" * 40


def test_the_image_ships_the_sandbox() -> None:
    found = image.dockerfile()
    # Bubblewrap for the namespaces, libseccomp for the seccomp filter.
    assert {"bubblewrap", "libseccomp2"} <= set(found["packages"]), found
    assert found["entrypoint"][1:] == ["-m", "worker.sandbox.container_init"], found
    # Debian 12's bubblewrap is 0.8.0, the oldest with --disable-userns (`MIN_BWRAP`).
    assert found["base"].endswith("-bookworm"), found


@pytest.mark.parametrize("name", image.SANDBOX_SERVICES)
def test_the_services_that_run_uploaded_code_get_the_sandbox_s_settings(name: str) -> None:
    service = image.services()[name]
    options = image.podman_options(service)  # every setting known
    assert "SYS_ADMIN" in service["cap_add"] and service["cgroup"] == "private"
    assert {"apparmor=unconfined", "systempaths=unconfined"} <= set(service["security_opt"])
    assert "--privileged" not in options
    settings = {**dict(service.get("environment") or {}),
                **_env_file(image.ROOT / ".env.example")}
    assert "FLYBO_SANDBOX_ALLOW_INSECURE" not in settings
    assert settings.get("FLYBO_ENVIRONMENT") == "production"


def test_settings_are_translated_to_podman_s_options() -> None:
    options = image.podman_options({"init": True, "mem_limit": "4g", "pids_limit": 512,
                                    "cap_drop": ["NET_RAW"], "cgroup": "host",
                                    "security_opt": ["no-new-privileges"], "ports": ["80:80"]})
    assert options[:4] == ["--cap-drop", "all", "--cap-add", ",".join(image.DOCKER_CAPABILITIES)]
    assert options[4:] == ["--init", "--memory", "4g", "--pids-limit", "512", "--cap-drop",
                           "NET_RAW", "--security-opt", "no-new-privileges", "--cgroupns", "host"]


def test_a_setting_it_cannot_reproduce_is_refused_by_name() -> None:
    with pytest.raises(image.UnknownSettingError, match="userns_mode"):
        image.podman_options({"cap_add": ["SYS_ADMIN"], "userns_mode": "host"})
    with pytest.raises(image.UnknownSettingError, match="security_opt 'systempaths=x'"):
        image.podman_options({"security_opt": ["systempaths=x"]})


def _env_file(path: Path) -> dict[str, str]:
    pairs = (line.split("=", 1) for line in path.read_text().splitlines()
             if "=" in line and not line.lstrip().startswith("#"))
    return {key.strip(): value.strip() for key, value in pairs}


@cache
def _podman() -> str | None:
    """Why podman cannot run a container here, or None when it can."""
    if shutil.which("podman") is None or shutil.which("runc") is None:
        return "podman and runc are not installed (make test-system-deps installs them)"
    done = subprocess.run(["podman", "--runtime", "runc", "run", "--rm", "--network", "none",
                           *image.host_ulimits(), "--rootfs", "/:O", "true"],
                          capture_output=True, text=True, timeout=300)
    if done.returncode != 0:
        return f"podman cannot run a container here: {done.stderr.strip()[-500:]}"
    return None


def _in_container(service: dict[str, Any], tmp_path: Path, *, probe_only: bool) -> Any:
    """Run `tests.sandbox.in_container` in a container of compose `service`; its report."""
    problem = _podman()
    if problem is not None:
        required(problem)
    options = image.podman_options(service)
    if not any(option.startswith("seccomp=") for option in options):
        profile = image.docker_seccomp_profile(tmp_path / "seccomp.json")
        options += ["--security-opt", f"seccomp={profile}"]
    entrypoint = [sys.executable, *image.dockerfile()["entrypoint"][1:]]
    command = [sys.executable, "-m", "tests.sandbox.in_container",
               *(["--probe-only"] if probe_only else [])]
    root = str(image.ROOT)
    done = subprocess.run(
        ["podman", "--runtime", "runc", "run", "--rm", *image.host_ulimits(), *options,
         # The host's network: a planner that reached it would reach the host's database.
         "--network", "host", "-v", f"{root}:{root}:ro", "-w", root,
         "-e", "FLYBO_ENVIRONMENT=production", "-e", f"FLYBO_SECRET_KEY={SECRET}",
         "-e", "PYTHONDONTWRITEBYTECODE=1", "--rootfs", "/:O", *entrypoint, *command],
        capture_output=True, text=True, timeout=600, env={**os.environ, "CI": ""})
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.mark.slow  # a container, and five flights in it
def test_the_containers_contain_hostile_planners(tmp_path: Path) -> None:
    distinct = {json.dumps(image.podman_options(image.services()[name])): name
                for name in image.SANDBOX_SERVICES}  # the same settings are tried once
    for name in distinct.values():
        _contains_hostile_planners(image.services()[name], tmp_path / name)


def _contains_hostile_planners(service: dict[str, Any], tmp_path: Path) -> None:
    tmp_path.mkdir()
    report = _in_container(service, tmp_path, probe_only=False)
    assert report["full"] and report["seccomp"] and report["uploads"] == "run", report
    flights = report["flights"]
    seen = flights["looks for secrets and the network"]
    # Neither its environment nor its PID 1's (bubblewrap's) holds the worker's settings.
    assert SECRET not in seen and "FLYBO_" not in seen, seen
    # Its own loopback, not the container's, where the host's database answers (when it runs
    # here: the container has the host's network).
    assert "'connect': (-1, " in seen, seen
    with socket.socket() as outside:
        outside.settimeout(2)
        assert report["database_reachable_outside"] == (outside.connect_ex(("127.0.0.1",
                                                                            5432)) == 0)
    assert "unshare gave -1 (Operation not permitted)" in flights["creates a user namespace"]
    assert "took longer than 30 s" in flights["forks without end"] \
        or "process" in flights["forks without end"], flights
    assert "memory limit of 512 MiB" in flights["allocates without end"], flights
    assert flights["honest"] == "succeeded", flights


def _without(setting: str) -> dict[str, Any]:
    service = dict(image.services()["worker"])
    if setting == "cap_add":
        service.pop("cap_add")
    else:
        service["security_opt"] = [o for o in service["security_opt"] if o != setting]
    return service


@pytest.mark.slow  # a container each
@pytest.mark.parametrize(("setting", "missing"), [
    ("cap_add", "no writable pids cgroup"),
    ("systempaths=unconfined", "bubblewrap cannot create namespaces here"),
    ("apparmor=unconfined", "bubblewrap cannot create namespaces here"),
])
def test_without_each_setting_uploads_are_refused(setting: str, missing: str,
                                                   tmp_path: Path) -> None:
    if setting.startswith("apparmor") and not Path("/sys/kernel/security/apparmor").exists():
        pytest.skip("this kernel has no AppArmor: the setting changes nothing here")
    report = _in_container(_without(setting), tmp_path, probe_only=True)
    assert not report["full"], report
    assert report["uploads"].startswith("refused: the planner sandbox is not available"), report
    assert any(missing in note for note in report["notes"]), report
