"""VAPIX, the client's side: build PTZ requests and parse the camera's replies (pure).

Documented limits: pan/tilt −180…180°, zoom 1…9999 (AXIS 215: 3.8–46 mm), speed 1…100.
Success is ``204`` (or ``200`` with data); a refused request is ``200`` with ``Error: ...``.
"""

from __future__ import annotations

from dataclasses import dataclass

from common.camera import PtzLimits

PTZ_PATH = "/axis-cgi/com/ptz.cgi"
IMAGE_PATH = "/axis-cgi/jpg/image.cgi"
PARAM_PATH = "/axis-cgi/param.cgi"
PICTURE_SIZES = "root.Properties.Image.Resolution"  # its sizes, the full picture first
_RANGES = {"pan": (-180.0, 180.0), "tilt": (-180.0, 180.0), "zoom": (1, 9999),
           "speed": (1, 100)}


@dataclass(frozen=True)
class Position:
    pan_deg: float
    tilt_deg: float
    zoom: int
    ir_cut_filter: str | None = None


def nudge_params(pan_deg: float = 0.0, tilt_deg: float = 0.0, zoom: int = 0
                 ) -> dict[str, str]:
    """Query parameters of a move relative to where the camera is (``rpan``, ``rtilt``,
    ``rzoom``): the camera adds them to its own position, whatever anyone last saw of it."""
    out: dict[str, str] = {}
    for name, value in (("rpan", pan_deg), ("rtilt", tilt_deg)):
        if value:
            out[name] = f"{min(max(float(value), -360.0), 360.0):.4f}"
    if zoom:
        out["rzoom"] = str(int(min(max(int(zoom), -9999), 9999)))
    return out


class VapixReplyError(ValueError):
    """A reply that is not what VAPIX specifies (the camera or something else answered)."""


def move_params(pan_deg: float | None = None, tilt_deg: float | None = None,
                zoom: int | None = None, speed: int | None = None) -> dict[str, str]:
    """Query parameters of an absolute move, clamped to VAPIX's documented ranges."""
    out: dict[str, str] = {}
    for name, value in (("pan", pan_deg), ("tilt", tilt_deg)):
        if value is not None:
            lo, hi = _RANGES[name]
            out[name] = f"{min(max(float(value), lo), hi):.4f}"
    for name, value in (("zoom", zoom), ("speed", speed)):
        if value is not None:
            lo, hi = _RANGES[name]
            out[name] = str(int(min(max(int(value), lo), hi)))
    return out


def error_message(body: str) -> str | None:
    """The camera's complaint if the body is an ``Error:`` reply, else None."""
    stripped = body.strip()
    return stripped[len("Error:"):].strip() if stripped.startswith("Error:") else None


def parse_values(body: str) -> dict[str, str]:
    """``key=value`` lines (CRLF or LF) into a dict."""
    values = {}
    for line in body.splitlines():
        key, sep, value = line.strip().partition("=")
        if sep:
            values[key.strip()] = value.strip()
    return values


def parse_position(body: str) -> Position:
    values = parse_values(body)
    try:
        return Position(float(values["pan"]), float(values["tilt"]),
                        int(float(values.get("zoom", "1"))), values.get("ircutfilter"))
    except (KeyError, ValueError) as err:
        raise VapixReplyError(f"not a position reply: {body[:80]!r}") from err


def parse_limits(body: str) -> PtzLimits:
    values = parse_values(body)
    try:
        return PtzLimits(float(values["MinPan"]), float(values["MaxPan"]),
                      float(values["MinTilt"]), float(values["MaxTilt"]),
                      int(float(values.get("MinZoom", "1"))),
                      int(float(values.get("MaxZoom", "9999"))))
    except (KeyError, ValueError) as err:
        raise VapixReplyError(f"not a limits reply: {body[:80]!r}") from err


def parse_picture(body: str) -> tuple[int, int]:
    """The camera's full picture (width, height) from ``param.cgi``'s list of its picture
    sizes (``root.Properties.Image.Resolution=1920x1080,1280x720,…``: the first)."""
    sizes = parse_values(body).get(PICTURE_SIZES, "")
    width, _, height = sizes.split(",")[0].strip().lower().partition("x")
    if not (width.isdigit() and height.isdigit() and 0 < int(width) <= 8192
            and 0 < int(height) <= 8192):
        raise VapixReplyError(f"no picture size in {body[:80]!r}")
    return int(width), int(height)


def parse_presets(body: str) -> list[str]:
    """Preset names from ``query=presetposcam`` (``presetposnoN=NAME`` lines)."""
    names = []
    for line in body.splitlines():
        key, sep, value = line.partition("=")
        if sep and key.strip().startswith("presetposno") and value.strip():
            names.append(value.strip())
    return names
