"""What ``stb foxglove`` does once its flags are parsed (services/recording/foxglove_cli.py
has the command): the bus to Foxglove, live, through foxglove-sdk's WebSocket server — the
typed channels of ``services.recording.typed`` and each key's JSON copy with its schema
(``json/<key>``), named as in a recording so that one layout serves both."""

from __future__ import annotations

import argparse
import json
import logging
import queue
import sys
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import zenoh
from pydantic import Field

from common import messages as m
from common.lab_paths import DEFAULT_HEIGHT_MAP
from common.node import stop_on_signals
from common.settings import LogLevel, ServiceSettings
from services.entry import ToolError, checked_key_exprs, tool_session, tool_settings
from services.recording.foxglove import json_copy
from services.recording.inner_tls import make_certificate
from services.recording.origin_gate import OriginGate
from services.recording.record import crater, decode, latest_samples
from services.recording.typed import CRATER, LabScene, Typed

if TYPE_CHECKING:  # foxglove-sdk is loaded when the bridge starts, not with the settings
    import foxglove
    from foxglove.websocket import ServerListener

log = logging.getLogger(__name__)
JSON_PREFIX = "json/"


class FoxgloveSettings(ServiceSettings):
    section = "foxglove"
    borrowed = {"height_map": "gantry"}  # the lab's crater, named once

    log_level: LogLevel = "WARNING"
    host: str = Field("127.0.0.1", description="address to serve Foxglove on; 0.0.0.0 for the "
                      "lab LAN")
    port: int = Field(8765, ge=0, le=65535, description="Foxglove's default is 8765")
    height_map: Path | None = Field(DEFAULT_HEIGHT_MAP, description="the crater in "
                                    "the 3D scene (.npz; [gantry] height_map unless set here); "
                                    "missing: a scene without it")
    scene_hz: float = Field(10.0, gt=0, le=100, description="3D scene updates a second")
    allowed_origins: list[str] = Field([], description="web pages (their Origin, e.g. "
                                       "\"https://app.foxglove.dev\") that may connect besides "
                                       "this machine's; a browser lets any page try")


class Bridge:
    """Bus samples in (queued by the Zenoh callback), Foxglove channels out (one thread)."""

    def __init__(self, prefix: str, scene: LabScene, context: foxglove.Context) -> None:
        import foxglove

        self._foxglove, self.prefix, self.scene, self.context = foxglove, prefix, scene, context
        self.channels: dict[str, foxglove.Channel] = {}
        self.queue: queue.SimpleQueue = queue.SimpleQueue()
        self.forwarded = 0
        self._thread = threading.Thread(target=self._run, name="foxglove-bridge", daemon=True)
        self._thread.start()

    def on_sample(self, sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.PUT:
            self.queue.put((str(sample.key_expr), sample.payload.to_bytes()))

    def _run(self) -> None:
        while (item := self.queue.get()) is not None:
            try:
                self._forward(*item)
            except Exception:  # noqa: BLE001 - one bad sample must not end the bridge
                log.exception("cannot forward a sample of %s", item[0])

    def _forward(self, key: str, payload: bytes) -> None:
        msg, topic, error = decode(self.prefix, key, payload)
        if msg is None:
            log.debug("%s: invalid sample (%s)", key, error)
            return
        when = msg.measured_s if isinstance(msg, m.Message) else time.time()
        copy = json_copy(msg)
        if copy is not None:
            data, schema = copy
            self._channel(JSON_PREFIX + key, schema=None if schema is None else schema[1],
                          schema_name=None if schema is None else schema[0]).log(
                data, log_time=round(when * 1e9))
        if isinstance(msg, m.Message):
            for typed in self.scene.on(msg, topic):
                self._typed(typed)
        self.forwarded += 1

    def _typed(self, typed: Typed) -> None:
        channel = self.channels.get(typed.topic)
        if channel is None:
            schema = self._foxglove.Schema(name=typed.schema_name,
                                           encoding=typed.schema_encoding,
                                           data=typed.schema_data)
            channel = self.channels[typed.topic] = self._foxglove.Channel(
                typed.topic, schema=schema, message_encoding=typed.message_encoding,
                context=self.context)
        channel.log(typed.data, log_time=round(typed.time_s * 1e9))

    def _channel(self, topic: str, *, schema: dict[str, Any] | None, schema_name: str | None
                 ) -> foxglove.Channel:
        channel = self.channels.get(topic)
        if channel is None:
            fox_schema = None if schema is None else self._foxglove.Schema(
                name=schema_name or topic, encoding="jsonschema",
                data=json.dumps(schema).encode())
            channel = self.channels[topic] = self._foxglove.Channel(
                topic, schema=fox_schema, message_encoding="json", context=self.context)
        return channel

    def close(self) -> None:
        self.queue.put(None)
        self._thread.join(timeout=5)


class _Listener:
    """A client that subscribes to the crater gets it with the next message.

    Only ``on_subscribe``, duck-typed (cast to foxglove-sdk's ``ServerListener`` Protocol
    where the server is started), as it has been since the bridge began."""

    def __init__(self, scene: LabScene) -> None:
        self.scene = scene

    def on_subscribe(self, client: object, channel: object) -> None:
        if getattr(channel, "topic", None) == CRATER:
            self.scene.resend_crater()


def serve(args: argparse.Namespace) -> int:
    import foxglove

    settings = tool_settings(FoxgloveSettings, args)
    exprs = checked_key_exprs(args.key_exprs or [f"{settings.bus.prefix}/**"])
    session = tool_session(settings)
    stop = threading.Event()
    restore = stop_on_signals(stop)
    scene = LabScene(crater(settings.height_map), scene_hz=settings.scene_hz)
    context = foxglove.Context()
    bridge = Bridge(settings.bus.prefix, scene, context)
    server = gate = None
    subscribers = []
    try:
        try:  # foxglove-sdk's server on a loopback port of its own, behind the Origin gate
            listener = cast("ServerListener", _Listener(scene))  # duck-typed: see _Listener
            inner = make_certificate()  # the inner link: only the gate can open it
            server = foxglove.start_server(name="stb-supervisor", host="127.0.0.1", port=0,
                                          context=context, server_listener=listener,
                                          tls_cert=inner.certificate_pem,
                                          tls_key=inner.key_pem)
            gate = OriginGate(settings.host, settings.port, server.port,
                              settings.allowed_origins, inner.client_context()).start()
        except (RuntimeError, OSError) as err:
            raise ToolError(f"cannot serve on {settings.host}:{settings.port}: {err}") from err
        subscribers = [session.declare_subscriber(e, bridge.on_sample) for e in exprs]
        for expr in exprs:  # what was published before we joined (camera poses)
            for sample in latest_samples(session, expr, timeout_s=1.0):
                bridge.on_sample(sample)
        print(f"stb foxglove: serving {' '.join(exprs)} on ws://{settings.host}:{gate.port} "
              "(Foxglove: Open connection → Foxglove WebSocket; layout: "
              "docs/foxglove-layout.json). Ctrl-C ends.", file=sys.stderr, flush=True)
        stop.wait()
    finally:
        for sub in subscribers:
            sub.undeclare()
        bridge.close()
        if gate is not None:
            gate.stop()
        if server is not None:
            server.stop()
        session.close()
        restore()
    print(f"stb foxglove: forwarded {bridge.forwarded} samples", file=sys.stderr)
    return 0
