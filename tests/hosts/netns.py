"""Hosts on one machine, for the tests of runs across hosts: network namespaces joined by veth
pairs to a bridge in a namespace of its own (nothing touches the machine's own network). The
bridge forgets addresses at once (ageing time 0), so it floods every frame to every port like a
hub: a host on it sees the traffic of the others, as a reader on a shared link would."""

from __future__ import annotations

import os
import shutil
import subprocess
from dataclasses import dataclass

SUBNET = "192.0.2"  # TEST-NET-1 (RFC 5737): documentation addresses, routed nowhere


def missing() -> str | None:
    """Why these tests cannot run here, or None."""
    if os.geteuid() != 0:
        return "network namespaces need root (the tests of runs across hosts run as root in CI)"
    if shutil.which("ip") is None:
        return "network namespaces need iproute2's `ip` (apt-get install iproute2)"
    probe = f"zprobe{os.getpid()}"
    made = subprocess.run(["ip", "netns", "add", probe], capture_output=True, text=True)
    if made.returncode:
        return f"cannot make a network namespace here: {made.stderr.strip()}"
    subprocess.run(["ip", "netns", "del", probe], capture_output=True)
    return None


def _ip(*args: str, netns: str | None = None) -> None:
    command = ["ip", *(["-n", netns] if netns else []), *args]
    done = subprocess.run(command, capture_output=True, text=True)
    if done.returncode:
        raise RuntimeError(f"{' '.join(command)}: {done.stderr.strip()}")


@dataclass
class Host:
    name: str  # its namespace
    address: str  # its IPv4 address on the shared link
    port: str  # its veth end on the bridge (in the bridge's namespace)

    def command(self, *argv: str) -> list[str]:
        """``argv`` run inside this host."""
        return ["ip", "netns", "exec", self.name, *argv]


class Network:
    """``hosts`` (names) on one shared link; removed by :meth:`remove` (also after a failure)."""

    def __init__(self, names: list[str]):
        tag = f"{os.getpid() % 100000}"
        self.bridge = f"zbr{tag}"
        self.hosts: dict[str, Host] = {}
        try:
            _ip("netns", "add", self.bridge)
            _ip("link", "set", "lo", "up", netns=self.bridge)
            _ip("link", "add", "br0", "type", "bridge", "ageing_time", "0", netns=self.bridge)
            _ip("link", "set", "br0", "up", netns=self.bridge)
            for i, name in enumerate(names, start=1):
                host = Host(f"z{name}{tag}", f"{SUBNET}.{i}", f"p{i}")
                self.hosts[name] = host
                _ip("netns", "add", host.name)
                _ip("link", "set", "lo", "up", netns=host.name)
                _ip(
                    "link",
                    "add",
                    "eth0",
                    "netns",
                    host.name,
                    "type",
                    "veth",
                    "peer",
                    "name",
                    host.port,
                    "netns",
                    self.bridge,
                )
                _ip("addr", "add", f"{host.address}/24", "dev", "eth0", netns=host.name)
                _ip("link", "set", "eth0", "up", netns=host.name)
                _ip("link", "set", host.port, "master", "br0", "up", netns=self.bridge)
        except Exception:
            self.remove()
            raise

    def __getitem__(self, name: str) -> Host:
        return self.hosts[name]

    def cut(self, name: str) -> None:
        """Pull the host's cable: its port on the bridge goes down (its TCP links see nothing)."""
        _ip("link", "set", self.hosts[name].port, "down", netns=self.bridge)

    def mend(self, name: str) -> None:
        _ip("link", "set", self.hosts[name].port, "up", netns=self.bridge)

    def remove(self) -> None:
        """Delete every namespace (their veth ends go with them)."""
        for host in self.hosts.values():
            subprocess.run(["ip", "netns", "del", host.name], capture_output=True)
        subprocess.run(["ip", "netns", "del", self.bridge], capture_output=True)

    def __enter__(self) -> Network:
        return self

    def __exit__(self, *exc) -> None:
        self.remove()
