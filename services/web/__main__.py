"""``stb web``: the operator's live page on http://HOST:PORT (default 127.0.0.1:8080).

A top view of the crater height map with the robot's track, the crane and its error circle,
each PTZ camera and where it looks; each camera's latest preview with the markers found and the
robot marker's expected pixel; every service's liveliness and health; the gravity-offload
figures. The page updates itself from the bus (Server-Sent Events), no reloading.

Subscribes: stb/tracker/robot, stb/gantry/{state,estimate,offload}, stb/ptz/*/{state,preview},
            stb/calib/*/pose (also queried at start), stb/health/**, stb/sim/truth/robot/*,
            stb/gantry/command/reply, liveliness stb/alive/**.
Publishes:  its own health and liveliness; stb/gantry/command when an operator presses one
            of the page's gantry buttons (arm, disarm, stop, reset).
"""

from __future__ import annotations

import logging
import sys
import threading
import time
from collections.abc import Sequence

import zenoh

from common import keys
from common.node import Node, StartupError
from services.entry import service_main
from services.web.commands import GantryCommander
from services.web.server import CraterImage, WebServer
from services.web.settings import WebSettings
from services.web.state import LiveState

log = logging.getLogger(__name__)
TOPICS = (keys.TRACKER_ROBOT, keys.CALIB_PROGRESS, keys.GANTRY_STATE, keys.GANTRY_ESTIMATE,
          keys.GANTRY_OFFLOAD, keys.PTZ_STATE, keys.PTZ_PREVIEW, keys.TRUTH_ROBOT)


def run(node: Node) -> None:
    settings: WebSettings = node.settings  # type: ignore[assignment]
    state = LiveState(track_s=settings.track_s)
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
        node.stop.wait()
    finally:
        server.close()
        tokens.undeclare()


def main(argv: Sequence[str] | None = None) -> int:
    return service_main("web", WebSettings, run, argv, __doc__ or "")


if __name__ == "__main__":
    sys.exit(main())
