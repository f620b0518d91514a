"""Hosts for tests: network namespaces joined by veth links to a bridge in the test's own
namespace (which is the lab switch; the test process sits on it as one more host)."""

from __future__ import annotations

import os
import shutil
import subprocess
import uuid
from dataclasses import dataclass, field


def why_not() -> str | None:
    """Why namespaces cannot be made here, or None if they can."""
    if os.geteuid() != 0:
        return "network namespaces need root"
    if shutil.which("ip") is None:
        return "the 'ip' command (iproute2) is missing"
    probe = f"stbprobe{uuid.uuid4().hex[:6]}"
    made = subprocess.run(["ip", "netns", "add", probe], capture_output=True, text=True)
    if made.returncode != 0:
        return f"cannot make a network namespace: {made.stderr.strip()}"
    subprocess.run(["ip", "netns", "delete", probe], capture_output=True)
    return None


def _ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, text=True)


@dataclass
class Lan:
    """A /24 on a bridge; ``host(name)`` adds a namespace with one address on it."""

    subnet: str = "10.213.7"
    tag: str = field(default_factory=lambda: uuid.uuid4().hex[:5])
    hosts: dict[str, tuple[str, str, str]] = field(default_factory=dict)  # name → ns, veth, ip

    def __post_init__(self) -> None:
        self.bridge = f"stbbr{self.tag}"
        _ip("link", "add", self.bridge, "type", "bridge")
        _ip("addr", "add", f"{self.subnet}.1/24", "dev", self.bridge)
        _ip("link", "set", self.bridge, "up")

    @property
    def gateway(self) -> str:
        """The test process's own address on the LAN."""
        return f"{self.subnet}.1"

    def host(self, name: str) -> str:
        index = len(self.hosts) + 2
        ns, outside, inside = f"stb{self.tag}{name}", f"stb{self.tag}{index}", f"stbin{index}"
        address = f"{self.subnet}.{index}"
        _ip("netns", "add", ns)
        _ip("link", "add", outside, "type", "veth", "peer", "name", inside, "netns", ns)
        _ip("link", "set", outside, "master", self.bridge, "up")
        _ip("-n", ns, "addr", "add", f"{address}/24", "dev", inside)
        _ip("-n", ns, "link", "set", inside, "up")
        _ip("-n", ns, "link", "set", "lo", "up")
        self.hosts[name] = (ns, outside, address)
        return address

    def namespace(self, name: str) -> str:
        return self.hosts[name][0]

    def cut(self, name: str) -> None:
        """Pull the host's cable (both directions)."""
        _ip("link", "set", self.hosts[name][1], "down")

    def plug(self, name: str) -> None:
        _ip("link", "set", self.hosts[name][1], "up")

    def close(self) -> None:
        for ns, outside, _ in self.hosts.values():
            subprocess.run(["ip", "link", "delete", outside], capture_output=True)
            subprocess.run(["ip", "netns", "delete", ns], capture_output=True)
        subprocess.run(["ip", "link", "delete", self.bridge], capture_output=True)
