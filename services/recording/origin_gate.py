"""A gate in front of foxglove-sdk's WebSocket server, which takes a connection from any web
page: a browser lets any page open a WebSocket to any address, and says only in the
handshake's ``Origin`` which page it is. The gate (the ``websockets`` library) serves
``[foxglove] host:port``, refuses a handshake from a foreign Origin (403, logged), and relays
each accepted connection's frames both ways to foxglove-sdk's server on a loopback port of
its own. Accepted: no Origin (Foxglove's desktop app, scripts: not a browser page), a page
served from this machine (``localhost``, ``127.0.0.1``, ``[::1]``, any port) and the
origins in ``[foxglove] allowed_origins`` (e.g. ``https://app.foxglove.dev``).
"""

from __future__ import annotations

import asyncio
import logging
import re
import ssl
import threading
from collections.abc import Sequence

from websockets.asyncio.client import ClientConnection, connect
from websockets.asyncio.server import Server, ServerConnection, serve
from websockets.exceptions import ConnectionClosed
from websockets.typing import Origin, Subprotocol

log = logging.getLogger(__name__)
SUBPROTOCOLS = [Subprotocol("foxglove.sdk.v1"), Subprotocol("foxglove.websocket.v1")]
LOOPBACK_ORIGIN = re.compile(r"https?://(localhost|127\.0\.0\.1|\[::1\])(:\d{1,5})?")


def accepted_origins(configured: Sequence[str]) -> list[Origin | re.Pattern[str] | None]:
    return [None, LOOPBACK_ORIGIN, *(Origin(o.rstrip("/")) for o in configured)]


class OriginGate:
    """Serves ``host:port`` in a thread of its own; relays to ``ws://127.0.0.1:upstream``
    (``wss://`` with ``upstream_tls``: ``inner_tls.py``)."""

    def __init__(self, host: str, port: int, upstream_port: int,
                 allowed_origins: Sequence[str] = (),
                 upstream_tls: ssl.SSLContext | None = None) -> None:
        scheme = "ws" if upstream_tls is None else "wss"
        self.host, self.port = host, port
        self.upstream = f"{scheme}://127.0.0.1:{upstream_port}"
        self.upstream_tls = upstream_tls
        self.origins = accepted_origins(allowed_origins)
        self._loop = asyncio.new_event_loop()
        self._server: Server | None = None
        self._started = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="foxglove-origin-gate",
                                         daemon=True)

    def start(self) -> OriginGate:
        """Listening when it returns; OSError if it cannot bind."""
        self._thread.start()
        self._started.wait(10)
        if self._error is not None:
            raise self._error
        return self

    def _run(self) -> None:
        asyncio.set_event_loop(self._loop)
        try:
            self._server = self._loop.run_until_complete(self._open())
            self.port = self._server.sockets[0].getsockname()[1]
        except OSError as err:
            self._error = err
            return
        finally:
            self._started.set()
        self._loop.run_forever()

    async def _open(self) -> Server:
        return await serve(self._relay, self.host, self.port, origins=self.origins,
                           subprotocols=SUBPROTOCOLS, compression=None, max_size=None,
                           process_response=_log_refusal)

    async def _relay(self, client: ServerConnection) -> None:
        protocols = [client.subprotocol] if client.subprotocol else SUBPROTOCOLS
        try:
            async with connect(self.upstream, subprotocols=protocols, compression=None,
                               max_size=None, open_timeout=5, ssl=self.upstream_tls) as server:
                pumps = [asyncio.create_task(_pump(client, server)),
                         asyncio.create_task(_pump(server, client))]
                _, pending = await asyncio.wait(pumps, return_when=asyncio.FIRST_COMPLETED)
                for task in pending:
                    task.cancel()
        except (OSError, TimeoutError, ConnectionClosed) as err:
            log.warning("foxglove: cannot relay a client: %s", err)

    def stop(self) -> None:
        async def close() -> None:
            if self._server is not None:
                self._server.close()
                await self._server.wait_closed()

        if self._thread.is_alive():
            asyncio.run_coroutine_threadsafe(close(), self._loop).result(timeout=10)
            self._loop.call_soon_threadsafe(self._loop.stop)
            self._thread.join(timeout=5)


async def _pump(source: ServerConnection | ClientConnection,
                sink: ServerConnection | ClientConnection) -> None:
    try:
        async for frame in source:
            await sink.send(frame)
    except ConnectionClosed:
        pass


def _log_refusal(connection: ServerConnection, request: object, response: object) -> None:
    if getattr(response, "status_code", 101) == 403:
        headers = getattr(request, "headers", {})
        log.warning("foxglove: refused a connection from %s: Origin %r is not this machine's "
                    "nor in [foxglove] allowed_origins", connection.remote_address,
                    headers.get("Origin"))
