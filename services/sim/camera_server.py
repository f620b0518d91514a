"""A simulated AXIS camera on HTTP: VAPIX, Digest (or Basic) authentication, JPEG snapshots
and an MJPEG stream — the AXIS 215 PTZ cameras (``SimCamera``: also PTZ control, parameters,
users) and any fixed camera that only takes pictures (``ServedCamera``: the crane's
observation camera, ``services.sim.observation``)."""

from __future__ import annotations

import base64
import contextlib
import hashlib
import hmac
import io
import logging
import secrets
import socket
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Literal, Protocol
from urllib.parse import parse_qsl, urlsplit

import cv2
import numpy as np

from common.trace import TRACE_HEADER
from services.sim import vapix
from services.sim.arrival import StampedReader
from services.sim.ptz import PtzHead
from services.sim.render import Glint, NoiseBank, draw, glint_blobs, marker_blobs
from services.sim.scene import DAY, INFRARED, GroundView, chassis_outline, compose
from services.sim.vapix_device import Device, api_discovery
from services.sim.vapix_ptz import CameraMemory, handle_ptz

log = logging.getLogger(__name__)

REALM = "AXIS_ACCC8E5A0215"
BOUNDARY = "myboundary"  # what AXIS cameras put between the JPEGs of video.cgi
NONCE_LIFETIME_S = 300.0
MAX_WAIT_S = 1.0  # a picture is of at most this long before its request was handled


class StampedHandler(BaseHTTPRequestHandler):
    """A request handler that knows when its request reached the camera (``arrived``, UNIX
    seconds; ``StampedReader``)."""

    arrived = 0.0


class ServedCamera(Protocol):
    """What the server needs of any camera: its name, credentials, pictures and their sizes
    (VAPIX names, the first is the default)."""

    name: str
    user: str
    password: str
    auth: Literal["digest", "basic", "none"]
    jpeg_quality: int
    mjpeg_fps: float
    resolutions: dict[str, tuple[int, int]]

    def snapshot(self, width: int, height: int, waited_s: float = 0.0) -> np.ndarray:
        """The picture of ``waited_s`` ago (when the request reached the camera)."""
        ...


@dataclass
class SimCamera:
    """What the server needs to play one camera: its head, its scene and its credentials."""

    name: str
    head: PtzHead
    scene: Callable[[float], np.ndarray]  # marker world points (N, 3) at a sim time
    glints: list[Glint]
    clock: Callable[[], float]
    rng: np.random.Generator
    user: str = "root"
    password: str = "pass"
    auth: Literal["digest", "basic", "none"] = "digest"
    jpeg_quality: int = 90
    mjpeg_fps: float = 2.0  # video.cgi's rate when the request names none
    ground: GroundView | None = None  # the crater as this camera sees it; None: a plain field
    robots: Callable[[float], list[tuple[np.ndarray, float, float]]] = lambda _t: []
    """(marker position, heading, ground height) of each robot at a sim time: their chassis
    are drawn"""
    memory: CameraMemory = field(default_factory=CameraMemory)
    resolutions: dict[str, tuple[int, int]] = field(default_factory=lambda: vapix.RESOLUTIONS)
    noise: dict[tuple[int, int], NoiseBank] = field(default_factory=dict)
    """the sensor's noise per picture size, drawn at the first picture of that size"""
    commands: deque[tuple[float, float]] = field(default_factory=lambda: deque(maxlen=100_000))
    """(arrival wall time, X-STB-Measured) of every traced PTZ command: latency figures. The
    arrival is the kernel's receive time of the bytes carrying the request line."""

    def snapshot(self, width: int, height: int, waited_s: float = 0.0) -> np.ndarray:
        """What the camera saw ``waited_s`` ago, when the request reached it: the crater and
        the robots (with a ``ground``; else a plain field), the markers — bright with the IR
        cut filter off — and the reflections. A real camera's sensor does not wait for its
        CPU; the sim's thread may wait for the sim's other work (on a busy machine tens of
        milliseconds), and the wand would be drawn where it was that much later. The head is
        drawn as it is now (it has no past; at rest while a picture is measured)."""
        now = self.clock()
        taken = now - waited_s
        pose = self.head.pose(now)
        intr = self.head.intrinsics(now, width, height)
        ir_visible = self.head.ir_cut_filter == "off"
        background: float | np.ndarray
        if self.ground is not None:
            look = INFRARED if ir_visible else DAY
            chassis = [hull for marker, heading, ground in self.robots(taken)
                       if (hull := chassis_outline(marker, heading, ground, pose, intr))
                       is not None]
            background = compose(self.ground.brightness(pose, intr), look, chassis)
            peak = look.marker_peak
        else:
            peak, background = (255.0, 16.0) if ir_visible else (70.0, 55.0)
        blobs = marker_blobs(self.scene(taken), pose, intr, peak=peak)
        if ir_visible:
            blobs += glint_blobs(self.glints, pose, intr)
        noise = self.noise.get((width, height))
        if noise is None:  # 2.5 gray levels (draw's own), whole levels: a quarter the bytes
            noise = self.noise[(width, height)] = NoiseBank(2.5, width, height, self.rng,
                                                            whole=True)
        return draw(blobs, width, height, self.rng, background=background, noise=noise)

    @property
    def device(self) -> Device:
        return Device(self.name, self.head, self.memory, self.user, self.resolutions)


def digest_challenge(secret: bytes, now: float) -> str:
    stamp = f"{now:.3f}"
    mac = hmac.new(secret, stamp.encode(), hashlib.sha256).hexdigest()[:16]
    nonce = base64.b64encode(f"{stamp}:{mac}".encode()).decode()
    return f'Digest realm="{REALM}", nonce="{nonce}", algorithm=MD5, qop="auth"'


def digest_ok(header: str, method: str, user: str, password: str, secret: bytes,
              now: float) -> bool:
    """Check an ``Authorization: Digest ...`` header (RFC 2617, MD5, qop=auth)."""
    fields = _parse_auth_fields(header[len("Digest "):])
    try:
        stamp, mac = base64.b64decode(fields["nonce"]).decode().split(":")
        fresh = now - float(stamp) < NONCE_LIFETIME_S
        genuine = hmac.compare_digest(
            mac, hmac.new(secret, stamp.encode(), hashlib.sha256).hexdigest()[:16])
        ha1 = _md5(f"{user}:{REALM}:{password}")
        ha2 = _md5(f"{method}:{fields['uri']}")
        expected = _md5(f"{ha1}:{fields['nonce']}:{fields['nc']}:{fields['cnonce']}:"
                        f"{fields['qop']}:{ha2}")
    except (KeyError, ValueError):
        return False
    return (fresh and genuine and fields.get("username") == user
            and hmac.compare_digest(expected, fields.get("response", "")))


def basic_ok(header: str, user: str, password: str) -> bool:
    try:
        given = base64.b64decode(header[len("Basic "):]).decode()
    except ValueError:
        return False
    return hmac.compare_digest(given, f"{user}:{password}")


def _md5(text: str) -> str:
    return hashlib.md5(text.encode()).hexdigest()  # noqa: S324 - RFC 2617 mandates MD5


def _parse_auth_fields(text: str) -> dict[str, str]:
    fields: dict[str, str] = {}
    for part in _split_commas(text):
        key, _, value = part.strip().partition("=")
        fields[key.strip()] = value.strip().strip('"')
    return fields


def _split_commas(text: str) -> list[str]:
    parts, current, quoted = [], "", False
    for char in text:
        if char == '"':
            quoted = not quoted
        if char == "," and not quoted:
            parts.append(current)
            current = ""
        else:
            current += char
    return [*parts, current]


def answer(cam: ServedCamera, path: str, args: dict[str, str], body: bytes,
           trace: str | None, arrived: float) -> vapix.Reply:
    """The camera's answer to an authorised request (every path but ``video.cgi``'s stream):
    what the server sends, and what a test's in-process client gets without a socket.
    ``trace``: the request's ``X-STB-Measured`` header; ``arrived``: when it reached the
    camera (wall time)."""
    if path == vapix.IMAGE_PATH:
        size = vapix.image_size(args, cam.resolutions)
        if isinstance(size, vapix.Reply):
            return size
        return jpeg_reply(cam, size, args,
                          waited_s=min(max(time.time() - arrived, 0.0), MAX_WAIT_S))
    if not isinstance(cam, SimCamera):  # a fixed camera: pictures only
        return vapix.not_found()
    now = cam.clock()
    if path == vapix.PTZ_PATH:
        if trace is not None:
            with contextlib.suppress(ValueError):  # a malformed trace header: not recorded
                cam.commands.append((arrived, float(trace)))
        return handle_ptz(args, cam.head, cam.memory, now)
    if path == vapix.PARAM_PATH:
        return cam.device.param_cgi(args, now)
    if path == vapix.BASIC_DEVICE_INFO_PATH:
        return cam.device.basic_device_info(body)
    if path == vapix.API_DISCOVERY_PATH:
        return api_discovery(body)
    if path == vapix.PWDGRP_PATH:
        return cam.device.users(args)
    if path == vapix.USERGROUP_PATH:
        return cam.device.user_groups()
    return vapix.not_found()


def jpeg_reply(cam: ServedCamera, size: tuple[int, int], args: dict[str, str],
               waited_s: float = 0.0) -> vapix.Reply:
    """A snapshot of what the camera saw when the request reached it (``waited_s`` ago), at
    its JPEG quality or the request's ``compression``."""
    image = cam.snapshot(*size, waited_s=waited_s)
    quality = cam.jpeg_quality
    if "compression" in args and args["compression"].isdigit():
        quality = max(5, 100 - int(args["compression"]))
    ok, jpeg = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        return vapix.error("image: encoding failed")
    return vapix.Reply(200, "image/jpeg", jpeg.tobytes())


class CameraServer:
    """Serves one camera on ``host:port`` from a background thread."""

    def __init__(self, camera: ServedCamera, host: str, port: int) -> None:
        self.camera = camera
        self._secret = secrets.token_bytes(16)
        self._closing = threading.Event()
        self._open: set[socket.socket] = set()  # the clients' connections, cut at close
        self._open_lock = threading.Lock()
        self._httpd = ThreadingHTTPServer((host, port), self._handler_class())
        self._httpd.daemon_threads = True
        self.port = self._httpd.server_address[1]
        # it looks for a shutdown every 50 ms (the standard half second made every close,
        # and every test's end, wait that long)
        self._thread = threading.Thread(target=self._httpd.serve_forever, args=(0.05,),
                                        name=f"vapix:{camera.name}", daemon=True)

    def start(self) -> CameraServer:
        self._thread.start()
        return self

    def close(self) -> None:
        """The camera gone (switched off, rebooting): no new connections, and the open ones
        (a client's keep-alive) cut."""
        self._closing.set()
        self._httpd.shutdown()
        self._httpd.server_close()
        with self._open_lock:
            for connection in self._open:
                with contextlib.suppress(OSError):  # closed by its client meanwhile
                    connection.shutdown(socket.SHUT_RDWR)

    def _handler_class(self) -> type[StampedHandler]:
        server = self

        class Handler(StampedHandler):
            server_version = "Boa/0.94.14rc21"  # what AXIS 2xx cameras announce
            protocol_version = "HTTP/1.1"

            def setup(self) -> None:
                super().setup()
                # Headers and body go out in two writes: without this, the body waits for
                # the client's delayed ACK of the headers (40 ms per snapshot back to back).
                self.connection.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                self.rfile.close()  # the plain reader: its reference would keep the socket open
                self._stamps = StampedReader(self.connection)
                self.rfile = io.BufferedReader(self._stamps)
                with server._open_lock:
                    server._open.add(self.connection)

            def finish(self) -> None:
                with server._open_lock:
                    server._open.discard(self.connection)
                super().finish()

            def parse_request(self) -> bool:
                # The request line has just been read: the command reached the camera when
                # the kernel received the bytes that carried it.
                self.arrived = self._stamps.arrived_s
                return super().parse_request()

            def do_GET(self) -> None:  # noqa: N802 - http.server's naming
                server._serve(self, "GET")

            def do_POST(self) -> None:  # noqa: N802
                server._serve(self, "POST")

            def log_message(self, fmt: str, *args: object) -> None:
                log.debug("%s %s", server.camera.name, fmt % args)

        return Handler

    def _serve(self, request: StampedHandler, method: str) -> None:
        arrived = request.arrived
        url = urlsplit(request.path)
        args = dict(parse_qsl(url.query, keep_blank_values=True))
        body = b""
        if method == "POST":
            length = request.headers.get("Content-Length") or "0"
            if not length.isdigit() or int(length) > 65536:
                self._send(request, vapix.Reply(400, "text/plain", b"Bad Request\r\n"))
                return
            body = request.rfile.read(int(length))
            if not request.headers.get("Content-Type", "").startswith("application/json"):
                args.update(parse_qsl(body.decode(errors="replace"), keep_blank_values=True))
        if not self._authorized(request, method):
            return
        if url.path == vapix.MJPEG_PATH:
            self._stream(request, args)
            return
        self._send(request, answer(self.camera, url.path, args, body,
                                   request.headers.get(TRACE_HEADER), arrived))

    def _authorized(self, request: BaseHTTPRequestHandler, method: str) -> bool:
        cam = self.camera
        header = request.headers.get("Authorization", "")
        if cam.auth == "none":
            return True
        if cam.auth == "digest" and header.startswith("Digest ") and digest_ok(
                header, method, cam.user, cam.password, self._secret, time.time()):
            return True
        if cam.auth == "basic" and header.startswith("Basic ") and basic_ok(
                header, cam.user, cam.password):
            return True
        challenge = (digest_challenge(self._secret, time.time()) if cam.auth == "digest"
                     else f'Basic realm="{REALM}"')
        request.send_response(401)
        request.send_header("WWW-Authenticate", challenge)
        body = b"401 Unauthorized\r\n"
        request.send_header("Content-Type", "text/plain")
        request.send_header("Content-Length", str(len(body)))
        request.end_headers()
        request.wfile.write(body)
        return False

    def _stream(self, request: BaseHTTPRequestHandler, args: dict[str, str]) -> None:
        """``video.cgi``: multipart JPEGs at ``fps`` (or the camera's rate) until the client
        leaves, ``duration`` seconds or ``nbrofframes`` frames are over, or the server closes."""
        asked = vapix.stream_request(args, self.camera.mjpeg_fps, self.camera.resolutions)
        if isinstance(asked, vapix.Reply):
            self._send(request, asked)
            return
        request.send_response(200)
        request.send_header("Content-Type", f"multipart/x-mixed-replace; boundary={BOUNDARY}")
        request.send_header("Cache-Control", "no-cache")
        request.send_header("Connection", "close")
        request.end_headers()
        request.close_connection = True
        started, sent = time.monotonic(), 0
        while not self._closing.is_set() and (asked.frames is None or sent < asked.frames) \
                and time.monotonic() - started < asked.duration_s:
            part = jpeg_reply(self.camera, asked.size, args)
            try:
                request.wfile.write(f"--{BOUNDARY}\r\nContent-Type: image/jpeg\r\n"
                                    f"Content-Length: {len(part.body)}\r\n\r\n".encode()
                                    + part.body + b"\r\n")
                request.wfile.flush()
            except OSError:  # the client left
                return
            sent += 1
            self._closing.wait(max(0.0, started + sent / asked.fps - time.monotonic()))

    @staticmethod
    def _send(request: BaseHTTPRequestHandler, reply: vapix.Reply) -> None:
        request.send_response(reply.status)
        request.send_header("Content-Type", reply.content_type)
        request.send_header("Content-Length", str(len(reply.body)))
        request.end_headers()
        if reply.body:
            request.wfile.write(reply.body)
