"""Test hosts on one machine: network namespaces joined by a bridge (iproute2).

Every address lives only inside namespaces this module creates; the bridge sits in its own
"switch" namespace, so the machine's own namespace gets no interface or address. Everything
is removed on exit, also when a test fails.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

SUBNET = "10.231.{}.{}"  # private range, only inside the test's namespaces


def _ip(*args: str, ns: str | None = None) -> None:
    cmd = ["ip", *(["-n", ns] if ns else []), *args]
    subprocess.run(cmd, check=True, capture_output=True, text=True)


def netns_available() -> str | None:
    """None when namespaces can be made here, else the reason they cannot."""
    if shutil.which("ip") is None:
        return "iproute2 (`ip`) is not installed"
    if os.geteuid() != 0:
        return "creating network namespaces needs root"
    probe = f"smprobe{os.getpid()}"
    try:
        _ip("netns", "add", probe)
    except subprocess.CalledProcessError as exc:
        return f"`ip netns add` failed: {exc.stderr.strip()}"
    _ip("netns", "del", probe)
    return None


@dataclass
class Hosts:
    """Named test hosts: `address[name]` and `exec_prefix(name)` for commands inside."""

    tag: str
    subnet: int
    address: dict[str, str] = field(default_factory=dict)
    veth: dict[str, str] = field(default_factory=dict)

    def ns(self, name: str) -> str:
        return f"{self.tag}-{name}"

    def exec_prefix(self, name: str) -> list[str]:
        return ["ip", "netns", "exec", self.ns(name)]

    def link(self, name: str, up: bool) -> None:
        """Cut or restore host `name`'s only link (its end of the veth pair)."""
        _ip("link", "set", "eth0", "up" if up else "down", ns=self.ns(name))


@contextmanager
def make_hosts(names: list[str]) -> Iterator[Hosts]:
    """Create one namespace per name on a shared bridge; remove them all afterwards."""
    tag = f"sm{os.getpid() % 100000}"
    hosts = Hosts(tag=tag, subnet=(os.getpid() % 200) + 20)
    switch = hosts.ns("switch")
    created: list[str] = []
    try:
        _ip("netns", "add", switch)
        created.append(switch)
        _ip("link", "add", "br0", "type", "bridge", ns=switch)
        _ip("link", "set", "br0", "up", ns=switch)
        for i, name in enumerate(names, start=1):
            ns = hosts.ns(name)
            _ip("netns", "add", ns)
            created.append(ns)
            _ip("link", "set", "lo", "up", ns=ns)
            peer = f"{tag[:8]}p{i}"
            _ip("link", "add", "eth0", "type", "veth", "peer", "name", peer, "netns", switch, ns=ns)
            _ip("link", "set", peer, "master", "br0", ns=switch)
            _ip("link", "set", peer, "up", ns=switch)
            address = SUBNET.format(hosts.subnet, i)
            _ip("addr", "add", f"{address}/24", "dev", "eth0", ns=ns)
            _ip("link", "set", "eth0", "up", ns=ns)
            hosts.address[name] = address
            hosts.veth[name] = peer
        yield hosts
    finally:
        for ns in reversed(created):
            subprocess.run(["ip", "netns", "del", ns], capture_output=True)
