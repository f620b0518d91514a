"""Free loopback ports for tests.

Taken below the kernel's ephemeral range: a port from that range (what binding port 0 gives)
can be handed to any outgoing connection — an HTTP client's, Zenoh's — between the test
choosing it and its server binding it ("Address already in use", seen in CI). Below it only
an explicit bind can take a port, and this process never hands out the same one twice.
"""

from __future__ import annotations

import random
import socket
from pathlib import Path

_handed_out: set[int] = set()
_random = random.Random()


def _ephemeral_start() -> int:
    try:
        return int(Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return 32768


def listening(port: int) -> bool:
    """Something accepts connections on the loopback ``port`` (a server has started)."""
    with socket.socket() as s:
        s.settimeout(0.5)
        return s.connect_ex(("127.0.0.1", port)) == 0


def free_port() -> int:
    top = _ephemeral_start()
    for _ in range(500):
        port = _random.randrange(10000, top) if top > 11000 else 0
        if port in _handed_out:
            continue
        with socket.socket() as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:
                continue
            port = s.getsockname()[1]
        _handed_out.add(port)
        return port
    raise RuntimeError("no free loopback port below the ephemeral range")
