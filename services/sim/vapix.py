"""VAPIX as the simulated AXIS 215 PTZ speaks it: paths and reply shapes (pure).

Written from the VAPIX documentation and the replies of real AXIS cameras (those recorded in
the `axis` library's tests), independently of our client's constants (``services/ptz/vapix``):
a wrong path on either side fails the tests against the other. A command that succeeds
answers ``204 No Content``; a refused one ``200`` with an ``Error:`` body, as the cameras do.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

PTZ_PATH = "/axis-cgi/com/ptz.cgi"
IMAGE_PATH = "/axis-cgi/jpg/image.cgi"
MJPEG_PATH = "/axis-cgi/mjpg/video.cgi"
PARAM_PATH = "/axis-cgi/param.cgi"
BASIC_DEVICE_INFO_PATH = "/axis-cgi/basicdeviceinfo.cgi"
API_DISCOVERY_PATH = "/axis-cgi/apidiscovery.cgi"
PWDGRP_PATH = "/axis-cgi/pwdgrp.cgi"
USERGROUP_PATH = "/axis-cgi/usergroup.cgi"

TEXT = "text/plain"
JSON = "application/json"
RESOLUTIONS = {"704x576": (704, 576), "352x288": (352, 288), "176x144": (176, 144)}


@dataclass(frozen=True)
class Reply:
    status: int
    content_type: str
    body: bytes


def ok() -> Reply:
    return Reply(204, TEXT, b"")


def error(message: str) -> Reply:
    return Reply(200, TEXT, f"Error: {message}\r\n".encode())


def text(lines: list[str]) -> Reply:
    return Reply(200, TEXT, ("\r\n".join(lines) + "\r\n").encode())


def not_found() -> Reply:
    return Reply(404, TEXT, b"Not Found\r\n")


class BadArgument(ValueError):
    pass


def number(args: Mapping[str, str], name: str) -> float | None:
    """A finite number argument, None when absent; BadArgument when it is not one."""
    if name not in args:
        return None
    try:
        value = float(args[name])
    except ValueError:
        raise BadArgument(f'{name}: invalid value "{args[name]}"') from None
    if value != value or value in (float("inf"), float("-inf")):
        raise BadArgument(f'{name}: invalid value "{args[name]}"')
    return value


def image_size(args: Mapping[str, str], resolutions: Mapping[str, tuple[int, int]] = RESOLUTIONS
               ) -> tuple[int, int] | Reply:
    """The requested resolution (``image.cgi``, ``video.cgi``) among the camera's
    ``resolutions`` (the first is its default), or an error reply."""
    if args.get("camera", "1") != "1":
        return error(f'camera: invalid value "{args["camera"]}"')
    resolution = args.get("resolution", next(iter(resolutions)))
    if resolution not in resolutions:
        return error(f'resolution: invalid value "{resolution}"')
    return resolutions[resolution]


@dataclass(frozen=True)
class StreamRequest:
    """What ``video.cgi`` was asked for."""

    size: tuple[int, int]
    fps: float
    duration_s: float  # inf: until the client leaves
    frames: int | None  # None: no limit


def stream_request(args: Mapping[str, str], default_fps: float,
                   resolutions: Mapping[str, tuple[int, int]] = RESOLUTIONS
                   ) -> StreamRequest | Reply:
    size = image_size(args, resolutions)
    if isinstance(size, Reply):
        return size
    try:
        fps, duration = number(args, "fps"), number(args, "duration")
        frames = number(args, "nbrofframes")
    except BadArgument as err:
        return error(str(err))
    fps = default_fps if fps is None else fps
    if not 0 < fps <= 30:
        return error(f'fps: invalid value "{args.get("fps")}"')
    if duration is not None and duration <= 0:
        return error(f'duration: invalid value "{args["duration"]}"')
    if frames is not None and (frames < 0 or frames != int(frames)):
        return error(f'nbrofframes: invalid value "{args["nbrofframes"]}"')
    return StreamRequest(size, fps, float("inf") if duration is None else duration,
                         int(frames) if frames else None)
