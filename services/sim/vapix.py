"""VAPIX as an AXIS 215 PTZ answers it: requests in, (status, content type, body) out (pure).

Success of a PTZ command is ``204 No Content``; a bad request is ``200`` with an ``Error:``
body, as the real cameras do. JPEG snapshots are rendered by the caller (see ``server.py``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from services.ptz.vapix import IMAGE_PATH, PTZ_PATH
from services.sim.ptz import PtzHead

TEXT = "text/plain"
__all__ = ["IMAGE_PATH", "PTZ_PATH", "handle_ptz", "snapshot_size"]
RESOLUTIONS = {"704x576": (704, 576), "352x288": (352, 288), "176x144": (176, 144)}

INFO = """\
Available commands for camera 1:
{pan,tilt}=<float>
{rpan,rtilt}=<float>
zoom=<int>
rzoom=<int>
speed=<int>
continuouspantiltmove=<int>,<int>
continuouszoommove=<int>
move={home|up|down|left|right|upleft|upright|downleft|downright|stop}
ircutfilter={on|off|auto}
query={position|limits|speed}
info=1
"""

_MOVES = {"up": (0, 5), "down": (0, -5), "left": (-5, 0), "right": (5, 0), "upleft": (-5, 5),
          "upright": (5, 5), "downleft": (-5, -5), "downright": (5, -5)}


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


class BadArgument(ValueError):
    pass


def _number(args: Mapping[str, str], name: str) -> float | None:
    if name not in args:
        return None
    try:
        value = float(args[name])
    except ValueError:
        raise BadArgument(f'{name}: invalid value "{args[name]}"') from None
    if value != value or value in (float("inf"), float("-inf")):
        raise BadArgument(f'{name}: invalid value "{args[name]}"')
    return value


def handle_ptz(args: Mapping[str, str], head: PtzHead, now: float) -> Reply:
    """One ``ptz.cgi`` request (GET query or POST form, already decoded)."""
    unknown = set(args) - {"pan", "tilt", "zoom", "rpan", "rtilt", "rzoom", "speed", "camera",
                           "continuouspantiltmove", "continuouszoommove", "move", "query",
                           "info", "ircutfilter", "imagewidth", "imageheight", "timestamp"}
    if unknown:
        return error(f'unknown argument "{sorted(unknown)[0]}"')
    if args.get("camera", "1") != "1":
        return error(f'camera: invalid value "{args["camera"]}"')
    try:
        if "query" in args:
            return _query(args["query"], head, now)
        if "info" in args:
            return Reply(200, TEXT, INFO.replace("\n", "\r\n").encode())
        return _command(args, head, now)
    except BadArgument as err:
        return error(str(err))


def _query(what: str, head: PtzHead, now: float) -> Reply:
    if what == "position":
        pan, tilt, zoom, _ = head.state(now)
        return text([f"pan={pan:.4f}", f"tilt={tilt:.4f}", f"zoom={zoom}", "iris=5000",
                     "focus=5000", "autofocus=on", "autoiris=on",
                     f"ircutfilter={head.ir_cut_filter}"])
    if what == "limits":
        lim = head.limits
        return text([f"MinPan={lim.min_pan:g}", f"MaxPan={lim.max_pan:g}",
                     f"MinTilt={lim.min_tilt:g}", f"MaxTilt={lim.max_tilt:g}",
                     f"MinZoom={lim.min_zoom}", f"MaxZoom={lim.max_zoom}",
                     "MinFieldAngle=44", "MaxFieldAngle=508"])
    if what == "speed":
        return text(["speed=100"])
    return error(f'query: unknown value "{what}"')


def _command(args: Mapping[str, str], head: PtzHead, now: float) -> Reply:
    if "ircutfilter" in args:
        if args["ircutfilter"] not in ("on", "off", "auto"):
            raise BadArgument(f'ircutfilter: invalid value "{args["ircutfilter"]}"')
        head.ir_cut_filter = args["ircutfilter"]
    speed = _number(args, "speed")
    if speed is not None and not 1 <= speed <= 100:
        raise BadArgument(f'speed: invalid value "{args["speed"]}"')
    absolute = [_number(args, k) for k in ("pan", "tilt", "zoom")]
    relative = [_number(args, k) for k in ("rpan", "rtilt", "rzoom")]
    if any(v is not None for v in absolute):
        head.absolute(now, *absolute, speed=speed)
    if any(v is not None for v in relative):
        head.relative(now, *(v or 0.0 for v in relative), speed=speed)
    if "continuouspantiltmove" in args:
        pan_pct, tilt_pct = _pair(args["continuouspantiltmove"])
        head.continuous(now, pan_pct, tilt_pct)
    if "continuouszoommove" in args:
        head.continuous(now, zoom_pct=_percent(args["continuouszoommove"],
                                               "continuouszoommove"))
    if "move" in args:
        _move(args["move"], head, now, speed)
    return ok()


def _move(where: str, head: PtzHead, now: float, speed: float | None) -> None:
    if where == "home":
        head.absolute(now, 0.0, 0.0, speed=speed)
    elif where == "stop":
        head.stop(now)
    elif where in _MOVES:
        head.relative(now, *_MOVES[where], speed=speed)
    else:
        raise BadArgument(f'move: invalid value "{where}"')


def _pair(value: str) -> tuple[float, float]:
    parts = value.split(",")
    if len(parts) != 2:
        raise BadArgument(f'continuouspantiltmove: invalid value "{value}"')
    return (_percent(parts[0], "continuouspantiltmove"),
            _percent(parts[1], "continuouspantiltmove"))


def _percent(value: str, name: str) -> float:
    try:
        pct = float(value)
    except ValueError:
        raise BadArgument(f'{name}: invalid value "{value}"') from None
    if not -100 <= pct <= 100:
        raise BadArgument(f'{name}: invalid value "{value}"')
    return pct


def snapshot_size(args: Mapping[str, str]) -> tuple[int, int] | Reply:
    """The requested resolution, or an error reply for an unsupported one."""
    if args.get("camera", "1") != "1":
        return error(f'camera: invalid value "{args["camera"]}"')
    resolution = args.get("resolution", "704x576")
    if resolution not in RESOLUTIONS:
        return error(f'resolution: invalid value "{resolution}"')
    return RESOLUTIONS[resolution]
