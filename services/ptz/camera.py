"""The PTZ camera driver: a small interface and the AXIS one (VAPIX over HTTP, httpx)."""

from __future__ import annotations

from typing import Protocol

import httpx
import numpy as np

from common.camera import PtzLimits
from common.jpeg import JpegError, decode_gray
from common.lab_views import CameraAuth, http_auth
from common.trace import TRACE_HEADER
from services.ptz import vapix


class PtzError(Exception):
    """Something went wrong talking to a PTZ camera."""


class PtzUnreachable(PtzError):
    """No answer: wrong address, camera off, network down, or a timeout."""


class PtzUnauthorized(PtzError):
    """The camera refused the credentials (HTTP 401/403)."""


class PtzRejected(PtzError):
    """The camera answered ``Error: ...`` (a request it does not accept)."""


class PtzCamera(Protocol):
    """A PTZ camera as the PTZ service drives it: move, go home, say where it looks and how far
    it can turn, take a snapshot, switch the IR-cut filter; errors are ``PtzError``.
    ``AxisPtzCamera`` is VAPIX's."""

    name: str

    def move_to(self, pan_deg: float | None, tilt_deg: float | None,
                zoom: int | None = None, speed: int | None = None,
                measured_s: float | None = None) -> None: ...

    def home(self) -> None: ...

    def nudge(self, pan_deg: float = 0.0, tilt_deg: float = 0.0, zoom: int = 0) -> None: ...

    def presets(self) -> list[str]: ...

    def goto_preset(self, name: str) -> None: ...

    def position(self) -> vapix.Position: ...

    def limits(self) -> PtzLimits: ...

    def picture(self) -> tuple[int, int]: ...

    def snapshot(self) -> np.ndarray: ...

    def snapshot_jpeg(self) -> bytes: ...

    def set_ir_cut_filter(self, mode: str) -> None: ...


class AxisPtzCamera:
    """An AXIS PTZ camera; ``client`` carries the base URL, authentication and timeouts."""

    def __init__(self, client: httpx.Client, name: str = "ptz") -> None:
        self.client = client
        self.name = name

    def move_to(self, pan_deg: float | None, tilt_deg: float | None,
                zoom: int | None = None, speed: int | None = None,
                measured_s: float | None = None) -> None:
        """Absolute move; ``measured_s`` (when the data behind it was measured) travels as a
        trace header that cameras ignore and the sim records, to measure the chain's latency."""
        headers = {TRACE_HEADER: f"{measured_s:.6f}"} if measured_s is not None else None
        self._request(vapix.PTZ_PATH, vapix.move_params(pan_deg, tilt_deg, zoom, speed),
                      headers)

    def home(self) -> None:
        """To the camera's home position (its home preset)."""
        self._request(vapix.PTZ_PATH, {"move": "home"})

    def nudge(self, pan_deg: float = 0.0, tilt_deg: float = 0.0, zoom: int = 0) -> None:
        """Relative to where the camera is now (an operator's ◀ ▶ ▲ ▼ ＋ －)."""
        self._request(vapix.PTZ_PATH, vapix.nudge_params(pan_deg, tilt_deg, zoom))

    def presets(self) -> list[str]:
        """The camera's own preset positions, by name."""
        return vapix.parse_presets(self._request(vapix.PTZ_PATH,
                                                 {"query": "presetposcam"}).text)

    def goto_preset(self, name: str) -> None:
        self._request(vapix.PTZ_PATH, {"gotoserverpresetname": name})

    def position(self) -> vapix.Position:
        return vapix.parse_position(self._request(vapix.PTZ_PATH, {"query": "position"}).text)

    def limits(self) -> PtzLimits:
        return vapix.parse_limits(self._request(vapix.PTZ_PATH, {"query": "limits"}).text)

    def picture(self) -> tuple[int, int]:
        """Its full picture's width and height (pixels), as it lists its picture sizes."""
        return vapix.parse_picture(self._request(
            vapix.PARAM_PATH, {"action": "list", "group": vapix.PICTURE_SIZES}).text)

    def set_ir_cut_filter(self, mode: str) -> None:
        if mode not in ("on", "off", "auto"):
            raise ValueError(f"IR cut filter mode must be on, off or auto, not {mode!r}")
        self._request(vapix.PTZ_PATH, {"ircutfilter": mode})

    def snapshot(self, resolution: str | None = None) -> np.ndarray:
        """The current image as a gray uint8 array."""
        return decode_jpeg(self.snapshot_jpeg(resolution), self.name)

    def snapshot_jpeg(self, resolution: str | None = None) -> bytes:
        """The current image as the camera sent it (JPEG), at ``resolution`` (VAPIX's
        ``WIDTHxHEIGHT``; None: the camera's own default, its full picture: an AXIS 215's
        704 × 576, a current camera's 1920 × 1080 — the picture's size comes with it)."""
        reply = self._request(vapix.IMAGE_PATH,
                              {} if resolution is None else {"resolution": resolution})
        if not reply.headers.get("content-type", "").startswith("image/jpeg"):
            raise PtzRejected(f"{self.name}: snapshot is not a JPEG")
        return reply.content

    def _request(self, path: str, params: dict[str, str],
                 headers: dict[str, str] | None = None) -> httpx.Response:
        """The one I/O call: every request goes through here and its errors are ours."""
        try:
            reply = self.client.get(path, params=params, headers=headers)
        except httpx.TransportError as err:
            raise PtzUnreachable(f"{self.name}: {type(err).__name__}: {err}") from err
        if reply.status_code in (401, 403):
            raise PtzUnauthorized(f"{self.name}: HTTP {reply.status_code} (check user/password)")
        if reply.status_code >= 400:
            raise PtzRejected(f"{self.name}: HTTP {reply.status_code} for {path}")
        if reply.headers.get("content-type", "").startswith("text/"):
            message = vapix.error_message(reply.text)
            if message is not None:
                raise PtzRejected(f"{self.name}: {message}")
        return reply


def decode_jpeg(data: bytes, name: str) -> np.ndarray:
    """A camera's JPEG as a gray uint8 array; PtzRejected if it does not decode."""
    try:
        return decode_gray(data)
    except JpegError as err:
        raise PtzRejected(f"{name}: snapshot: {err}") from err


def http_client(url: str, user: str, password: str, auth: CameraAuth = "digest",
                timeout_s: float = 2.0) -> httpx.Client:
    """An httpx client for one camera: Digest (AXIS default) or Basic auth, bounded timeouts."""
    return httpx.Client(base_url=url, auth=http_auth(user, password, auth),
                        timeout=httpx.Timeout(timeout_s))
