"""The production image's sandbox settings, read from `Dockerfile` and `docker-compose.yml`, and
the same container reproduced with podman where no Docker engine runs (the test machine).

The container's file system is this machine's own (`--rootfs /:O`, an overlay, so the container
writes nothing back), which is the image's: the same Debian release as the image's base, with
the packages the Dockerfile installs, and the project read-only at its path here. What Docker
adds to every container is added as Docker does it: its default capabilities (the rest
dropped), its default seccomp profile (podman's own, with the namespace and mount calls allowed
only to `CAP_SYS_ADMIN`, as Docker's profile allows them) and the masked system paths. Every
compose setting of a service that runs uploaded code is either translated to podman's option or
refused by name, so a setting this reproduction does not know cannot pass unnoticed.
"""

from __future__ import annotations

import json
import resource
import shlex
from pathlib import Path
from typing import Any

import yaml

ROOT = Path(__file__).resolve().parents[2]
DOCKERFILE = ROOT / "Dockerfile"
COMPOSE = ROOT / "docker-compose.yml"
# The services that run uploaded code: the API (the upload's dry run) and the workers (runs).
SANDBOX_SERVICES = ("api", "worker")
# Docker's default capabilities; a container has these and its `cap_add`, no others.
DOCKER_CAPABILITIES = ("AUDIT_WRITE", "CHOWN", "DAC_OVERRIDE", "FOWNER", "FSETID", "KILL",
                       "MKNOD", "NET_BIND_SERVICE", "NET_RAW", "SETFCAP", "SETGID", "SETPCAP",
                       "SETUID", "SYS_CHROOT")
# Compose keys that do not change what a process in the container may do.
NOT_ISOLATION = {"build", "image", "env_file", "ports", "expose", "volumes", "depends_on",
                 "healthcheck", "command", "deploy", "restart", "labels", "logging",
                 "container_name", "hostname", "environment", "stop_grace_period", "stop_signal",
                 "networks", "extra_hosts", "dns", "profiles", "working_dir", "tty",
                 "stdin_open"}
# Compose keys of a plain `--key value` podman option.
SAME_OPTION = {"mem_limit": "--memory", "pids_limit": "--pids-limit", "shm_size": "--shm-size",
               "cpus": "--cpus", "user": "--user"}
PODMAN_SECCOMP = Path("/usr/share/containers/seccomp.json")
# Calls Docker's default profile allows only with CAP_SYS_ADMIN; `clone` also without it when
# it asks for no new namespace (CLONE_NEWNS | NEWCGROUP | NEWUTS | NEWIPC | NEWUSER | NEWPID |
# NEWNET), and `clone3`, whose flags a filter cannot read, fails with ENOSYS (glibc falls back).
ADMIN_ONLY_CALLS = ("clone", "clone3", "unshare", "mount", "umount", "umount2", "pivot_root",
                    "setns")
NAMESPACE_FLAGS = 0x7E020000


class UnknownSettingError(ValueError):
    """A compose setting that this reproduction does not translate."""


def dockerfile() -> dict[str, Any]:
    """What the Dockerfile says: its base image, the Debian packages it installs and its
    entry point."""
    text = DOCKERFILE.read_text().replace("\\\n", " ")
    base, packages, entrypoint = "", [], []
    for line in text.splitlines():
        words = line.split()
        if not words or words[0].startswith("#"):
            continue
        if words[0] == "FROM":
            base = words[1]
        elif words[0] == "RUN" and "apt-get" in words and "install" in words:
            for command in " ".join(words[1:]).split("&&"):
                parts = shlex.split(command)
                if "install" in parts and "apt-get" in parts:
                    tail = parts[parts.index("install") + 1:]
                    packages += [p for p in tail if not p.startswith("-")]
        elif words[0] == "ENTRYPOINT":
            entrypoint = json.loads(line.split(None, 1)[1])
    return {"base": base, "packages": packages, "entrypoint": entrypoint}


def services() -> dict[str, dict[str, Any]]:
    """The compose file's services, with their `<<` merges applied."""
    data = yaml.safe_load(COMPOSE.read_text())
    return dict(data["services"])


def _security_opts(options: list[str]) -> list[str]:
    args = []
    for option in options:
        key, _, value = option.partition("=")
        if key == "apparmor":
            # No AppArmor on a kernel without it: there is nothing to confine or unconfine.
            args += ["--security-opt", f"apparmor={value}"]
        elif key == "systempaths" and value == "unconfined":
            args += ["--security-opt", "unmask=ALL"]
        elif key in ("seccomp", "no-new-privileges", "label"):
            args += ["--security-opt", option]
        else:
            raise UnknownSettingError(f"security_opt {option!r}")
    return args


def podman_options(service: dict[str, Any]) -> list[str]:
    """podman's options for a container of compose `service` (Docker's defaults included);
    `UnknownSettingError` for a setting that changes isolation and is not translated."""
    args = ["--cap-drop", "all", "--cap-add", ",".join(DOCKER_CAPABILITIES)]
    cgroupns = "private"  # Docker's default on cgroup v2 hosts, and what compose asks for
    for key, value in service.items():
        if key in NOT_ISOLATION:
            continue
        if key == "cap_add":
            args += ["--cap-add", ",".join(value)]
        elif key == "cap_drop":
            args += ["--cap-drop", ",".join(value)]
        elif key == "cgroup":
            cgroupns = str(value)
        elif key == "security_opt":
            args += _security_opts(list(value))
        elif key == "privileged":
            args += ["--privileged"] if value else []
        elif key in ("read_only", "init"):
            args += [f"--{key.replace('_', '-')}"] if value else []
        elif key in SAME_OPTION:
            args += [SAME_OPTION[key], str(value)]
        else:
            raise UnknownSettingError(f"{key}: {value!r}")
    return [*args, "--cgroupns", cgroupns]


def docker_seccomp_profile(path: Path) -> Path:
    """Write to `path` podman's default seccomp profile with the namespace and mount calls
    allowed as Docker's default profile allows them (`ADMIN_ONLY_CALLS`)."""
    profile = json.loads(PODMAN_SECCOMP.read_text())
    kept = []
    for rule in profile["syscalls"]:
        names = [name for name in rule["names"] if name not in ADMIN_ONLY_CALLS]
        # The calls' own rules are replaced by Docker's below; other calls keep theirs.
        if names:
            kept.append({**rule, "names": names})
    admin = {"caps": ["CAP_SYS_ADMIN"]}
    kept += [
        {"names": list(ADMIN_ONLY_CALLS), "action": "SCMP_ACT_ALLOW", "includes": admin},
        {"names": ["clone"], "action": "SCMP_ACT_ALLOW", "excludes": admin,
         "args": [{"index": 0, "value": NAMESPACE_FLAGS, "valueTwo": 0,
                   "op": "SCMP_CMP_MASKED_EQ"}]},
        {"names": ["clone3"], "action": "SCMP_ACT_ERRNO", "errnoRet": 38, "excludes": admin},
    ]
    path.write_text(json.dumps({**profile, "syscalls": kept}))
    return path


def host_ulimits() -> list[str]:
    """Open-file and process limits the container can be given here: podman's defaults for
    root are higher than the test machine's root may set. Neither bounds the sandbox, which
    sets its own (`SandboxLimits`) and has its pids cgroup."""
    nofile = resource.getrlimit(resource.RLIMIT_NOFILE)[1]
    nproc = min(resource.getrlimit(resource.RLIMIT_NPROC)[1], 4096)
    return ["--ulimit", f"nofile={nofile}:{nofile}", "--ulimit", f"nproc={nproc}:{nproc}"]
