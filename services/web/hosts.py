"""Which names the page answers to (pure): a DNS-rebinding page (another site whose name
is made to point at the lab PC) sends its own name in ``Host`` and is refused (421) before
anything else is looked at — on the open page (no users file) it once read the CSRF token
from ``/session.json`` and pressed the gantry's buttons.

Answered: an IP address literal (a rebinding page cannot be served under the lab PC's
address), ``localhost`` and ``*.localhost``, this machine's host names, and the names in
``[web] server_names`` (the name the lab's browsers use, a reverse proxy's)."""

from __future__ import annotations

import contextlib
import ipaddress
import socket
from collections.abc import Iterable

from starlette.responses import PlainTextResponse
from starlette.types import ASGIApp, Receive, Scope, Send


def own_names() -> set[str]:
    """This machine's host names, short and qualified."""
    names = {socket.gethostname()}
    with contextlib.suppress(OSError):
        names.add(socket.getfqdn())
    return {n.lower() for n in names if n}


class HostCheck:
    def __init__(self, names: Iterable[str]) -> None:
        self.names = {n.lower().rstrip(".") for n in names}

    def allows(self, host_header: str | None) -> bool:
        """Whether a request with this ``Host`` header is for the page."""
        if not host_header:
            return False
        host = host_header.strip().lower()
        if host.startswith("["):  # [::1]:8080
            host = host[1:host.find("]")] if "]" in host else host
        elif host.count(":") == 1:
            host = host.rsplit(":", 1)[0]
        host = host.rstrip(".")
        try:
            ipaddress.ip_address(host)
            return True
        except ValueError:
            pass
        return host == "localhost" or host.endswith(".localhost") or host in self.names


class HostGate:
    """ASGI middleware: a request (or WebSocket) for another name is answered 421."""

    def __init__(self, app: ASGIApp, check: HostCheck) -> None:
        self.app, self.check = app, check

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] in ("http", "websocket"):
            host = next((v.decode("latin-1") for k, v in scope.get("headers", [])
                         if k == b"host"), None)
            if not self.check.allows(host):
                if scope["type"] == "websocket":
                    await send({"type": "websocket.close", "code": 1008})
                    return
                response = PlainTextResponse(
                    "this page does not answer to that name (Host); add it to [web] "
                    "server_names", 421)
                await response(scope, receive, send)
                return
        await self.app(scope, receive, send)
