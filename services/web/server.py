"""Serving the page's application (``app.py``) with uvicorn on a thread of its own, over TLS
when a certificate and key are given."""

from __future__ import annotations

import logging
import socket
import threading
from collections.abc import Sequence
from pathlib import Path

import uvicorn
from starlette.applications import Starlette

log = logging.getLogger(__name__)


class WebServer:
    """Binds and loads the TLS files at construction (an ``OSError`` if the port is taken or a
    file is bad), serves from ``start``."""

    def __init__(self, app: Starlette, host: str, port: int,
                 tls: tuple[Path, Path] | None = None, proxies: Sequence[str] = ()) -> None:
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self._socket = socket.socket(family, socket.SOCK_STREAM)
        self._socket.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self._socket.bind((host, port))
            self._socket.listen(128)
        except OSError:
            self._socket.close()
            raise
        certificate, key = tls if tls else (None, None)
        config = uvicorn.Config(app, log_level="warning", access_log=False, lifespan="off",
                                ssl_certfile=certificate, ssl_keyfile=key,
                                timeout_graceful_shutdown=1, ws="none",
                                # X-Forwarded-For only from the lab's proxies (uvicorn's
                                # default trusts it from loopback: any local process)
                                proxy_headers=bool(proxies),
                                forwarded_allow_ips=list(proxies) or [])
        try:
            config.load()  # a bad certificate or key: an error now, not on the thread
        except OSError:
            self._socket.close()
            raise
        self.server = uvicorn.Server(config)
        self.scheme = "https" if tls else "http"
        self._thread = threading.Thread(target=self._serve, name="web-http", daemon=True)

    @property
    def port(self) -> int:
        return int(self._socket.getsockname()[1])

    def start(self) -> WebServer:
        self._thread.start()
        return self

    def _serve(self) -> None:
        try:
            self.server.run(sockets=[self._socket])
        except Exception:  # noqa: BLE001 - logged; the service's health shows the page gone
            log.exception("the page's server ended")

    def close(self, timeout_s: float = 5.0) -> None:
        self.server.should_exit = True
        self._thread.join(timeout_s)
        self._socket.close()
