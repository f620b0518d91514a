"""The operator's live page as a service: see ``services/web/__main__.py`` (``stb web``)."""

from __future__ import annotations

import logging
import threading
import time
from pathlib import Path
from typing import Any

import zenoh

from common import keys
from common import messages as m
from common.errors import StartupError
from common.keys import Topic
from common.node import Node
from common.settings import bus_environment
from services.web.app import build_app
from services.web.commands import GantryCommander
from services.web.console import Console
from services.web.crater_image import CraterImage
from services.web.doctor_desk import DoctorDesk
from services.web.gate import Gate
from services.web.hosts import HostCheck, own_names
from services.web.recordings import RecordingDesk
from services.web.server import WebServer
from services.web.settings import WebSettings
from services.web.state import LiveState
from services.web.users import Users, UsersFileError

log = logging.getLogger(__name__)
JUDGE_PERIOD_S = 0.5  # alarms begin and end on time even while no page looks
TOPICS: tuple[Topic[Any], ...] = (
    keys.TRACKER_ROBOT, keys.CALIB_PROGRESS, keys.GANTRY_STATE, keys.GANTRY_ESTIMATE,
    keys.GANTRY_OFFLOAD, keys.PTZ_STATE, keys.PTZ_PREVIEW, keys.PTZ_SNAPSHOT,
    keys.PTZ_DETECTIONS, keys.TRUTH_ROBOT)
# the page's command history
COMMAND_TOPICS: tuple[Topic[Any], ...] = (keys.GANTRY_COMMAND, keys.GANTRY_COMMAND_REPLY)


def open_gate(settings: WebSettings) -> Gate:
    """Who may use the page: the users file's users, or (loopback only) everyone here."""
    session_s = settings.session_h * 3600
    if settings.users_file is None:
        log.warning("no users_file: the page on %s is open to everyone on this machine, as "
                    "operator (add users with: stb web user add NAME --role operator)",
                    settings.host)
        return Gate(None, session_s, tls=settings.tls is not None)
    try:
        users = Users.load(settings.users_file)
    except UsersFileError as err:
        raise StartupError(str(err)) from err
    if not len(users):
        raise StartupError(f"users file {settings.users_file} has no users: add one with "
                           f"stb web user add NAME --role operator --users "
                           f"{settings.users_file}")
    log.info("%d users may sign in (%s)", len(users), settings.users_file)
    return Gate(users, session_s, tls=settings.tls is not None)


def run(node: Node[WebSettings], lab: Path | None = None) -> None:
    settings = node.settings
    gate = open_gate(settings)
    state = LiveState(track_s=settings.track_s, history_s=settings.history_s)
    lock = threading.Lock()

    def on_message(msg: m.Message) -> None:
        with lock:
            state.on_message(msg)

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

    def video(camera: str) -> bytes | None:
        with lock:
            return state.video_jpeg(camera)

    def on_video(frame: m.CameraFrame) -> None:
        with lock:
            state.on_video(frame)

    for topic in TOPICS:
        node.bus.subscribe(topic, on_message)
    for topic in COMMAND_TOPICS:
        node.bus.subscribe(topic, on_message, latest=False)
    node.bus.subscribe(keys.VIDEO, on_video)
    node.bus.subscribe(keys.HEALTH, on_message, latest=True)
    node.bus.subscribe(keys.CALIB_POSE, on_message, latest=False)
    for pose in node.bus.query_latest(keys.CALIB_POSE, timeout_s=1.0):
        on_message(pose)
    tokens = node.bus.session.liveliness().declare_subscriber(
        keys.alive_pattern(node.bus.prefix), on_alive, history=True)
    desk = RecordingDesk(settings.recordings_dir, bus_environment(settings.bus),
                         settings.height_map)
    crater = CraterImage(settings.height_map)
    app = build_app(gate, view, preview, video, crater,
                    push_period_s=1 / settings.push_hz, max_streams=settings.max_streams,
                    command=GantryCommander(node.bus, settings.bus.zenoh.identity("web")).send,
                    console=Console(node.bus, desk, settings.calibration_count,
                                    DoctorDesk(bus_environment(settings.bus), lab)),
                    hosts=HostCheck([*settings.server_names, *own_names()]))
    try:
        server = WebServer(app, settings.host, settings.port, settings.tls,
                           settings.trusted_proxies)
    except OSError as err:
        tokens.undeclare()
        raise StartupError(f"cannot serve on {settings.host}:{settings.port}: {err}") from err
    server.start()
    log.info("operator page on %s://%s:%d/", server.scheme, settings.host, server.port)
    try:
        while not node.stop.wait(JUDGE_PERIOD_S):
            with lock:
                state.judge(time.time())
            waiting = crater.waiting_for()  # the page still serves; the map comes when written
            node.set_status("degraded" if waiting else "ok", waiting)
    finally:
        server.close()
        desk.close()
        tokens.undeclare()
