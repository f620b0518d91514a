"""A camera's video as an AXIS camera streams it: VAPIX MJPEG (``/axis-cgi/mjpg/video.cgi``),
read by ``stb record --video CAMERA`` and by ``stb camera`` for the observation camera, each
JPEG stamped when it arrived (the same clock as every recorded bus sample, so that video,
mocap and gantry line up), each stamp later than the one before (``ArrivalStamps``: two JPEGs
that came in one read — a busy machine's backlog — would otherwise share one, and a video's
frames must follow each other in time).

``MjpegParts`` splits the multipart stream (pure); ``CameraVideo`` keeps a connection to one
camera — Digest, Basic or no auth as its ``CameraConnection`` says — and reconnects after a
failure, waiting 1 s doubling to 10 s; nothing it meets ends the recording."""

from __future__ import annotations

import logging
import re
import threading
import time
from collections.abc import Callable

import httpx

from common.backoff import Backoff
from common.lab_views import CameraConnection

log = logging.getLogger(__name__)
VIDEO_PATH = "/axis-cgi/mjpg/video.cgi"
MAX_PART_BYTES = 4 * 1024 * 1024
_BOUNDARY = re.compile(r'boundary="?([^";]+)"?', re.IGNORECASE)
_LENGTH = re.compile(rb"^content-length:\s*(\d+)\s*$", re.IGNORECASE | re.MULTILINE)


class ArrivalStamps:
    """When each frame arrived, by ``clock``, and always later than the frame before: a frame
    that arrived in the same read as the one before it (or after the wall clock was set back)
    is stamped ``STEP_S`` after that one."""

    STEP_S = 1e-6

    def __init__(self, clock: Callable[[], float] = time.time) -> None:
        self._clock = clock
        self._last_s = float("-inf")

    def next(self) -> float:
        self._last_s = max(self._clock(), self._last_s + self.STEP_S)
        return self._last_s


class VideoError(Exception):
    """The camera's answer is not a video stream: says why."""


def boundary_of(content_type: str) -> str:
    """The boundary of a ``multipart/x-mixed-replace`` stream; VideoError otherwise."""
    if not content_type.lower().startswith("multipart/"):
        raise VideoError(f"not a video stream (Content-Type {content_type!r})")
    found = _BOUNDARY.search(content_type)
    if not found:
        raise VideoError(f"no boundary in {content_type!r}")
    return found.group(1)


class MjpegParts:
    """Feed the stream's bytes as they come; get each whole JPEG part. Parts with a
    Content-Length are cut by it, others at the next boundary; a part larger than
    ``max_part_bytes`` is dropped (and counted) and the parser finds the next boundary."""

    def __init__(self, boundary: str, max_part_bytes: int = MAX_PART_BYTES) -> None:
        self.delimiter = b"--" + boundary.removeprefix("--").encode()
        self.max_part_bytes = max_part_bytes
        self.dropped = 0
        self._buffer = bytearray()

    def feed(self, chunk: bytes) -> list[bytes]:
        self._buffer += chunk
        parts = []
        while (part := self._next()) is not None:
            if part:
                parts.append(part)
        if len(self._buffer) > 2 * self.max_part_bytes:  # no delimiter in sight: start over
            self.dropped += 1
            del self._buffer[:-len(self.delimiter)]
        return parts

    def _next(self) -> bytes | None:
        """A part (b"" for one dropped), or None until more bytes come."""
        buffer = self._buffer
        start = buffer.find(self.delimiter)
        if start < 0:
            return None
        headers_end = buffer.find(b"\r\n\r\n", start)
        if headers_end < 0:
            return None
        headers = bytes(buffer[start:headers_end])
        body = headers_end + 4
        length = _LENGTH.search(headers)
        if length is not None:
            size = int(length.group(1))
            if size > self.max_part_bytes:
                self.dropped += 1
                del buffer[:body]
                return b""
            if len(buffer) < body + size:
                return None
            part = bytes(buffer[body:body + size])
            del buffer[:body + size]
            return part
        end = buffer.find(self.delimiter, body)
        if end < 0:
            return None
        part = bytes(buffer[body:end]).rstrip(b"\r\n")
        del buffer[:end]
        return part


class CameraVideo:
    """One camera's MJPEG stream on a thread of its own: ``on_frame(camera, jpeg, received_s)``
    for every JPEG; ``stop()`` ends it. ``resolution``: VAPIX's ``WIDTHxHEIGHT``, or "" for the
    camera's own default (its full picture)."""

    def __init__(self, name: str, connection: CameraConnection, fps: float, resolution: str,
                 on_frame: Callable[[str, bytes, float], None], timeout_s: float = 5.0) -> None:
        self.name, self.connection, self.on_frame = name, connection, on_frame
        self.params = {"fps": f"{fps:g}"} | ({"resolution": resolution} if resolution else {})
        self.timeout_s = timeout_s
        self.frames = 0
        self.problem = ""
        self._stamps = ArrivalStamps()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"video-{name}", daemon=True)

    def start(self) -> CameraVideo:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=self.timeout_s + 1)

    def _run(self) -> None:
        backoff = Backoff(1.0, 10.0)
        while not self._stop.is_set():
            try:
                self._stream()
                backoff.succeeded()
            except (httpx.HTTPError, VideoError, OSError) as err:
                problem = f"{type(err).__name__}: {err}" if str(err) else type(err).__name__
                if problem != self.problem:
                    log.warning("video of %s: %s (trying again)", self.name, problem)
                self.problem = problem
            self._stop.wait(backoff.failed())  # a stream that ended is opened again too

    def _stream(self) -> None:
        timeout = httpx.Timeout(self.timeout_s, read=self.timeout_s)
        with httpx.Client(base_url=self.connection.url.rstrip("/"), timeout=timeout,
                          auth=self.connection.http_auth()) as client, \
                client.stream("GET", VIDEO_PATH, params=self.params) as reply:
            if reply.status_code != 200:
                raise VideoError(f"{VIDEO_PATH} answered HTTP {reply.status_code}")
            parts = MjpegParts(boundary_of(reply.headers.get("content-type", "")))
            if self.problem:
                log.info("video of %s: streaming again", self.name)
                self.problem = ""
            for chunk in reply.iter_raw():
                for jpeg in parts.feed(chunk):
                    self.frames += 1
                    self.on_frame(self.name, jpeg, self._stamps.next())
                if self._stop.is_set():
                    return
