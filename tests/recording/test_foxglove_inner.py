"""The inner link of ``stb foxglove``: foxglove-sdk's server behind the Origin gate speaks TLS
with a certificate only the gate holds, so a page that finds its loopback port cannot read
the bus there (it once served every channel to ``Origin: evil.example``)."""

from __future__ import annotations

import asyncio
import json
import ssl

import foxglove
import pytest
import websockets

from services.recording.inner_tls import make_certificate
from services.recording.origin_gate import OriginGate


async def _server_info(url: str, origin: str | None, context: ssl.SSLContext | None) -> str:
    async with websockets.connect(url, origin=origin,  # type: ignore[arg-type]
                                  subprotocols=["foxglove.sdk.v1"],  # type: ignore[list-item]
                                  ssl=context, open_timeout=5) as ws:
        return str(json.loads(await asyncio.wait_for(ws.recv(), 5))["op"])


def test_only_the_gate_opens_the_inner_server() -> None:
    inner = make_certificate()
    server = foxglove.start_server(name="inner-test", host="127.0.0.1", port=0,
                                   context=foxglove.Context(), tls_cert=inner.certificate_pem,
                                   tls_key=inner.key_pem)
    gate = OriginGate("127.0.0.1", 0, server.port, (), inner.client_context()).start()
    try:
        assert asyncio.run(_server_info(f"ws://127.0.0.1:{gate.port}", None, None)) == \
            "serverInfo", "through the gate"
        evil = "https://evil.example"
        with pytest.raises((OSError, websockets.InvalidMessage, websockets.InvalidHandshake,
                            asyncio.TimeoutError, TimeoutError)):
            asyncio.run(_server_info(f"ws://127.0.0.1:{server.port}", evil, None))  # plain
        with pytest.raises(ssl.SSLCertVerificationError):  # as a browser would: no trust
            asyncio.run(_server_info(f"wss://127.0.0.1:{server.port}", evil,
                                     ssl.create_default_context()))
    finally:
        gate.stop()
        server.stop()
