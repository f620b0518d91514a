"""The page's HTTP side (standard library only): static files, the height map as an image, the
live state as JSON and as a Server-Sent Events stream, and each camera's latest preview.

    GET /                 the page            GET /events       text/event-stream of the state
    GET /state.json       the state once      GET /map.json     height map extent (mm)
    GET /map.png          the height map      GET /preview/CAMERA.jpg   latest preview
    POST /gantry/arm|disarm|stop|reset        an operator's command; the gantry's answer as JSON
                          (needs the header X-STB-Command: 1, which a page from another site
                          cannot send without this server's consent — it never gives it)
"""

from __future__ import annotations

import json
import logging
import re
import threading
import time
from collections.abc import Callable
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from common.heightmap import HeightMap

log = logging.getLogger(__name__)
STATIC = {"/": ("index.html", "text/html; charset=utf-8"),
          "/app.js": ("app.js", "text/javascript; charset=utf-8")}
DEFAULT_EXTENT_MM = (-3000.0, 3000.0, -3000.0, 3000.0)
PREVIEW_PATH = re.compile(r"^/preview/([A-Za-z0-9_.-]{1,64})\.jpg$")
COMMAND_PATH = re.compile(r"^/gantry/(arm|disarm|stop|reset)$")


COLOURS = "terrain"  # matplotlib's; it loads when the map is first drawn, not at start-up
SCALE_STEPS = 11  # colours the page's scale is drawn from, lowest to highest


def map_png(height_map: HeightMap) -> bytes:
    """The height map as a colour PNG, row 0 at the top = the largest y (north up)."""
    from matplotlib import colormaps

    h = height_map.heights_mm.astype(float)
    span = float(h.max() - h.min()) or 1.0
    rgba = colormaps[COLOURS]((h - h.min()) / span)
    bgr = (rgba[::-1, :, 2::-1] * 255).astype(np.uint8)
    ok, png = cv2.imencode(".png", np.ascontiguousarray(bgr))
    if not ok:
        raise ValueError("height map does not encode as PNG")
    return png.tobytes()


def map_info(height_map: HeightMap) -> dict[str, Any]:
    """The map's extent and its colour scale: the lowest and highest height and the colours
    between them, as the PNG shows them."""
    from matplotlib import colormaps

    h = height_map.heights_mm
    steps = colormaps[COLOURS](np.linspace(0.0, 1.0, SCALE_STEPS))
    return {"extent_mm": list(height_map.extent_mm), "image": True,
            "height_mm": [round(float(h.min()), 1), round(float(h.max()), 1)],
            "colours": ["#{:02x}{:02x}{:02x}".format(*(int(round(c * 255)) for c in rgba[:3]))
                        for rgba in steps]}


class CraterImage:
    """The height map as the page gets it, read when first asked for and again (at most every
    ``retry_s``) while the file is missing: the sim may write it after the page started."""

    def __init__(self, path: Path | None, retry_s: float = 2.0) -> None:
        self.path, self.retry_s = path, retry_s
        self._lock = threading.Lock()
        self._tried_at = -float("inf")
        self.info = json.dumps({"extent_mm": DEFAULT_EXTENT_MM, "image": False})
        self.png: bytes | None = None

    def get(self) -> tuple[str, bytes | None]:
        with self._lock:
            if self.png is None and self.path is not None and (
                    time.monotonic() - self._tried_at >= self.retry_s):
                self._tried_at = time.monotonic()
                self._load(self.path)
            return self.info, self.png

    def _load(self, path: Path) -> None:
        if not path.exists():
            return
        try:
            height_map = HeightMap.load(path)
            self.png = map_png(height_map)
        except ValueError as err:
            log.error("height map not shown: %s", err)
            self.path = None  # a broken file stays broken: do not read it every request
            return
        self.info = json.dumps(map_info(height_map))
        log.info("height map %s shown", path)


class WebServer:
    """Serves ``view()`` (the state dict) and ``preview(camera)`` (JPEG bytes or None)."""

    def __init__(self, host: str, port: int, view: Callable[[], dict[str, Any]],
                 preview: Callable[[str], bytes | None], crater: CraterImage,
                 push_period_s: float, stop: threading.Event,
                 command: Callable[[str, str], dict] | None = None) -> None:
        self.view, self.preview, self.stop, self.command = view, preview, stop, command
        self.push_period_s = push_period_s
        self.crater = crater
        self.httpd = ThreadingHTTPServer((host, port), self._handler())
        self.httpd.daemon_threads = True
        self._thread = threading.Thread(target=self.httpd.serve_forever, name="web-http",
                                        daemon=True)

    @property
    def port(self) -> int:
        return self.httpd.server_address[1]

    def start(self) -> WebServer:
        self._thread.start()
        return self

    def close(self) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()

    def _handler(self) -> type[BaseHTTPRequestHandler]:
        server = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, fmt: str, *args: object) -> None:
                log.debug("%s %s", self.address_string(), fmt % args)

            def do_GET(self) -> None:  # noqa: N802 - the http.server API
                path = self.path.split("?", 1)[0]
                try:
                    if path in STATIC:
                        name, kind = STATIC[path]
                        self._send(resources.files("services.web").joinpath(
                            "static", name).read_bytes(), kind)
                    elif path == "/state.json":
                        self._send(json.dumps(server.view()).encode(), "application/json")
                    elif path == "/map.json":
                        self._send(server.crater.get()[0].encode(), "application/json")
                    elif path == "/map.png" and (png := server.crater.get()[1]) is not None:
                        self._send(png, "image/png")
                    elif path == "/events":
                        self._events()
                    elif (found := PREVIEW_PATH.match(path)) and (
                            jpeg := server.preview(found.group(1))) is not None:
                        self._send(jpeg, "image/jpeg")
                    else:
                        self.send_error(HTTPStatus.NOT_FOUND)
                except (BrokenPipeError, ConnectionResetError):
                    pass  # the browser went away

            def do_POST(self) -> None:  # noqa: N802 - the http.server API
                found = COMMAND_PATH.match(self.path.split("?", 1)[0])
                if not found or server.command is None:
                    self.send_error(HTTPStatus.NOT_FOUND)
                    return
                if self.headers.get("X-STB-Command") != "1":
                    self.send_error(HTTPStatus.FORBIDDEN, "needs the X-STB-Command: 1 header")
                    return
                answer = server.command(found.group(1), self.client_address[0])
                self._send(json.dumps(answer).encode(), "application/json")

            def _send(self, body: bytes, kind: str, cache: bool = False) -> None:
                self.send_response(HTTPStatus.OK)
                self.send_header("Content-Type", kind)
                self.send_header("Content-Length", str(len(body)))
                self.send_header("Cache-Control", "max-age=3600" if cache else "no-store")
                self.end_headers()
                self.wfile.write(body)

            def _events(self) -> None:
                self.send_response(HTTPStatus.OK)
                self.send_header("Content-Type", "text/event-stream")
                self.send_header("Cache-Control", "no-store")
                self.end_headers()
                while not server.stop.is_set():
                    started = time.monotonic()
                    self.wfile.write(b"data: " + json.dumps(server.view()).encode() + b"\n\n")
                    self.wfile.flush()
                    server.stop.wait(max(0.0, server.push_period_s
                                         - (time.monotonic() - started)))

        return Handler
