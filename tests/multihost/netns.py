"""Hosts on one machine: Linux network namespaces joined by veth pairs to a bridge.

One namespace plays the server host (API, PostgreSQL, Redis, the artifact store), the others
worker hosts; each sees the others only through its link, so taking a link down cuts that host
off as a pulled cable would. Needs root and iproute2 (`apt-get install iproute2`).
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager, suppress
from dataclasses import dataclass, field
from pathlib import Path

import pytest

SUBNET = "10.231.{n}.0/24"


def netns_reason() -> str | None:
    """Why namespaces cannot be made here, or None."""
    if shutil.which("ip") is None:
        return "iproute2's `ip` is missing (apt-get install iproute2)"
    if os.geteuid() != 0:
        return "network namespaces need root"
    return None


def require_netns() -> None:
    """Skip without namespaces; under CI=true, where they must be made, fail instead."""
    reason = netns_reason()
    if reason is None:
        return
    if os.environ.get("CI") == "true":
        pytest.fail(f"{reason}; under CI=true this test must run")
    pytest.skip(f"{reason}; set CI=true to make this a failure")


def ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, text=True)


@dataclass
class Host:
    """One namespace, its address on the bridge and its link's name inside it."""

    name: str
    address: str
    link: str
    procs: list[subprocess.Popen[bytes]] = field(default_factory=list)

    def command(self, argv: Sequence[str]) -> list[str]:
        return ["ip", "netns", "exec", self.name, *argv]

    def start(self, argv: Sequence[str], env: dict[str, str], log: Path,
              user: str | None = None) -> subprocess.Popen[bytes]:
        """A process in this host's namespace (as `user` if given), in a group of its own."""
        run_as = ["runuser", "-u", user, "--"] if user else []
        with log.open("ab") as out:
            proc = subprocess.Popen(self.command([*run_as, *argv]), env=env, stdout=out,
                                    stderr=subprocess.STDOUT, start_new_session=True)
        self.procs.append(proc)
        return proc

    def pids(self) -> set[int]:
        """The processes living in this namespace now."""
        done = subprocess.run(["ip", "netns", "pids", self.name], capture_output=True,
                              text=True, check=True)
        return {int(p) for p in done.stdout.split()}

    def set_link(self, up: bool) -> None:
        ip("-n", self.name, "link", "set", self.link, "up" if up else "down")

    def stop(self) -> None:
        for proc in self.procs:
            with suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGTERM)
        deadline = time.monotonic() + 20
        for proc in self.procs:
            try:
                proc.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                with suppress(ProcessLookupError):
                    os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
        # Whatever else was left in the namespace (a worker's pool process, say).
        for pid in self.pids():
            with suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)


@contextmanager
def hosts(count: int) -> Iterator[list[Host]]:
    """`count` namespaces on one bridge (in the first), the first at .1: the server host; this
    process's namespace joins the bridge at .254 as the client (deleting the namespaces
    deletes every link made here)."""
    tag = f"{os.getpid() % 100000}"
    n = 1 + os.getpid() % 250
    bridge = f"fbbr{tag}"
    made: list[Host] = []
    try:
        for i in range(count):
            name = f"flybo-{tag}-{i}"
            ip("netns", "add", name)
            made.append(Host(name, SUBNET.format(n=n).replace("0/24", str(i + 1)), "eth0"))
            ip("-n", name, "link", "set", "lo", "up")
        server = made[0]
        ip("-n", server.name, "link", "add", bridge, "type", "bridge")
        ip("-n", server.name, "addr", "add", f"{server.address}/24", "dev", bridge)
        ip("-n", server.name, "link", "set", bridge, "up")
        server.link = bridge
        for i, host in enumerate(made[1:], start=1):
            outer = f"fb{tag}v{i}"
            ip("link", "add", outer, "netns", server.name, "type", "veth", "peer", "name",
               host.link, "netns", host.name)
            ip("-n", server.name, "link", "set", outer, "master", bridge)
            ip("-n", server.name, "link", "set", outer, "up")
            ip("-n", host.name, "addr", "add", f"{host.address}/24", "dev", host.link)
            ip("-n", host.name, "link", "set", host.link, "up")
        # The test itself (this namespace) reaches the hosts as a client on the same bridge.
        client = f"fb{tag}c"
        ip("link", "add", client, "type", "veth", "peer", "name", f"fb{tag}s", "netns",
           server.name)
        ip("-n", server.name, "link", "set", f"fb{tag}s", "master", bridge)
        ip("-n", server.name, "link", "set", f"fb{tag}s", "up")
        ip("addr", "add", SUBNET.format(n=n).replace("0/24", "254/24"), "dev", client)
        ip("link", "set", client, "up")
        yield made
    finally:
        for host in reversed(made):
            host.stop()
        for host in made:
            with suppress(subprocess.CalledProcessError):
                ip("netns", "del", host.name)
        with suppress(subprocess.CalledProcessError):  # gone with its peer, normally
            ip("link", "del", f"fb{tag}c")
