"""The operator's live page as a service: see ``services/web/__main__.py`` (``stb web``)."""

from __future__ import annotations

import logging
import threading
import time

import zenoh

from common import keys
from common.node import Node, StartupError
from services.web.commands import GantryCommander
from services.web.server import CraterImage, WebServer
from services.web.settings import WebSettings
from services.web.state import LiveState

log = logging.getLogger(__name__)
JUDGE_PERIOD_S = 0.5  # alarms begin and end on time even while no page looks
TOPICS = (keys.TRACKER_ROBOT, keys.CALIB_PROGRESS, keys.GANTRY_STATE, keys.GANTRY_ESTIMATE,
          keys.GANTRY_OFFLOAD, keys.PTZ_STATE, keys.PTZ_PREVIEW, keys.PTZ_SNAPSHOT,
          keys.PTZ_DETECTIONS, keys.TRUTH_ROBOT)


def run(node: Node[WebSettings]) -> None:
    settings = node.settings
    state = LiveState(track_s=settings.track_s, history_s=settings.history_s)
    lock = threading.Lock()

    def on_message(msg: object) -> None:
        with lock:
            state.on_message(msg)  # type: ignore[arg-type]

    def on_alive(sample: zenoh.Sample) -> None:
        parsed = keys.parse_alive(node.bus.prefix, str(sample.key_expr))
        if parsed:
            with lock:
                state.on_alive(*parsed, alive=sample.kind == zenoh.SampleKind.PUT)

    def view() -> dict:
        with lock:
            return state.view(time.time())

    def preview(camera: str) -> bytes | None:
        with lock:
            return state.preview_jpeg(camera)

    for topic in TOPICS:
        node.bus.subscribe(topic, on_message)
    node.bus.subscribe(keys.HEALTH, on_message, latest=True)
    node.bus.subscribe(keys.CALIB_POSE, on_message, latest=False)
    for pose in node.bus.query_latest(keys.CALIB_POSE, timeout_s=1.0):
        on_message(pose)
    tokens = node.bus.session.liveliness().declare_subscriber(
        keys.alive_pattern(node.bus.prefix), on_alive, history=True)
    try:
        server = WebServer(settings.host, settings.port, view, preview,
                           CraterImage(settings.height_map), 1 / settings.push_hz, node.stop,
                           GantryCommander(node.bus).send)
    except OSError as err:
        tokens.undeclare()
        raise StartupError(f"cannot listen on {settings.host}:{settings.port}: {err}") from err
    server.start()
    log.info("operator page on http://%s:%d/", settings.host, server.port)
    try:
        while not node.stop.wait(JUDGE_PERIOD_S):
            with lock:
                state.judge(time.time())
    finally:
        server.close()
        tokens.undeclare()
