"""``ptz.cgi`` as the simulated AXIS 215 PTZ answers it (pure): moves, lens, server presets,
queries.

Presets live in the camera (``setserverpresetname``/``no``, ``gotoserverpresetname``/``no``,
``removeserverpresetname``/``no``); preset 1 is ``Home`` at pan 0, tilt 0, zoom 1, where
``move=home`` goes. Setting ``focus`` or ``iris`` by hand turns its automation off, as the
camera does; ``autofocus=on`` turns it on again.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from services.sim.ptz import PtzHead
from services.sim.vapix import BadArgument, Reply, error, number, ok, text

DRIVER = "AXIS_215_PTZ"  # what ``whoami=1`` names

_LENS = ("focus", "iris", "rfocus", "riris", "autofocus", "autoiris")
_PRESETS = ("setserverpresetname", "setserverpresetno", "removeserverpresetname",
            "removeserverpresetno", "gotoserverpresetname", "gotoserverpresetno")
_ARGS = {"pan", "tilt", "zoom", "rpan", "rtilt", "rzoom", "speed", "camera",
         "continuouspantiltmove", "continuouszoommove", "move", "query", "info", "whoami",
         "ircutfilter", "imagewidth", "imageheight", "timestamp", *_LENS, *_PRESETS}
_MOVES = {"up": (0, 5), "down": (0, -5), "left": (-5, 0), "right": (5, 0), "upleft": (-5, 5),
          "upright": (5, 5), "downleft": (-5, -5), "downright": (5, -5)}

INFO = """\
Available commands
:
{camera=[n]}
whoami=yes
move={ home | up | down | left | right | upleft | upright | downleft | downright | stop }
pan=[abspos]
tilt=[abspos]
zoom=[n]
focus=[n]
iris=[n]
rpan=[offset]
rtilt=[offset]
rzoom=[offset]
rfocus=[offset]
riris=[offset]
autofocus={ on | off }
autoiris={ on | off }
ircutfilter={ on | off | auto }
continuouspantiltmove=[x-speed],[y-speed]
continuouszoommove=[speed]
setserverpresetname=[name]
setserverpresetno=[n]
removeserverpresetname=[name]
removeserverpresetno=[n]
gotoserverpresetname=[name]
gotoserverpresetno=[n]
speed=[n]
query={ speed | position | limits | mode | presetposcam | presetposall }
"""


@dataclass
class Preset:
    name: str
    pan: float
    tilt: float
    zoom: float


HOME = Preset("Home", 0.0, 0.0, 1.0)  # preset 1, where move=home goes


@dataclass
class CameraMemory:
    """What the camera keeps beside the head's motion: its server presets and its lens."""

    presets: dict[int, Preset] = field(
        default_factory=lambda: {1: HOME})
    autofocus: bool = True
    autoiris: bool = True
    focus: int = 5000
    iris: int = 5000

    def number_of(self, name: str) -> int | None:
        return next((no for no, p in self.presets.items() if p.name == name), None)


def handle_ptz(args: Mapping[str, str], head: PtzHead, memory: CameraMemory,
               now: float) -> Reply:
    """One ``ptz.cgi`` request (GET query or POST form, already decoded)."""
    unknown = set(args) - _ARGS
    if unknown:
        return error(f'unknown argument "{sorted(unknown)[0]}"')
    if args.get("camera", "1") != "1":
        return error(f'camera: invalid value "{args["camera"]}"')
    try:
        if "query" in args:
            return _query(args["query"], head, memory, now)
        if "info" in args:
            return Reply(200, "text/plain", INFO.replace("\n", "\r\n").encode())
        if "whoami" in args:
            return text([DRIVER])
        _lens(args, memory)
        _presets(args, head, memory, now)
        _move(args, head, memory, now)
        return ok()
    except BadArgument as err:
        return error(str(err))


def _query(what: str, head: PtzHead, memory: CameraMemory, now: float) -> Reply:
    if what == "position":
        pan, tilt, zoom, _ = head.state(now)
        on_off = {True: "on", False: "off"}
        return text([f"pan={pan:.4f}", f"tilt={tilt:.4f}", f"zoom={zoom}",
                     f"iris={memory.iris}", f"focus={memory.focus}",
                     f"autofocus={on_off[memory.autofocus]}",
                     f"autoiris={on_off[memory.autoiris]}",
                     f"ircutfilter={head.ir_cut_filter}"])
    if what == "limits":
        lim = head.limits
        return text([f"MinPan={lim.min_pan:g}", f"MaxPan={lim.max_pan:g}",
                     f"MinTilt={lim.min_tilt:g}", f"MaxTilt={lim.max_tilt:g}",
                     f"MinZoom={lim.min_zoom}", f"MaxZoom={lim.max_zoom}",
                     "MinIris=1", "MaxIris=9999", "MinFocus=1", "MaxFocus=9999",
                     "MinFieldAngle=44", "MaxFieldAngle=508"])
    if what == "speed":
        return text(["speed=100"])
    if what == "mode":
        return text(["mode=normal"])
    if what in ("presetposall", "presetposcam"):
        return text(["Preset Positions for camera 1",
                     *(f"presetposno{no}={p.name}" for no, p in sorted(memory.presets.items()))])
    return error(f'query: unknown value "{what}"')


def _lens(args: Mapping[str, str], memory: CameraMemory) -> None:
    for name in ("autofocus", "autoiris"):
        if name in args:
            if args[name] not in ("on", "off"):
                raise BadArgument(f'{name}: invalid value "{args[name]}"')
            setattr(memory, name, args[name] == "on")
    for name in ("focus", "iris"):
        absolute, relative = number(args, name), number(args, "r" + name)
        if absolute is None and relative is None:
            continue
        value = absolute if absolute is not None else getattr(memory, name) + relative
        setattr(memory, name, int(min(max(round(value), 1), 9999)))
        setattr(memory, "auto" + name, False)


def _presets(args: Mapping[str, str], head: PtzHead, memory: CameraMemory,
             now: float) -> None:
    if "setserverpresetname" in args or "setserverpresetno" in args:
        pan, tilt, zoom, _ = head.state(now)
        no, name = _preset_to_set(args, memory)
        memory.presets[no] = Preset(name, pan, tilt, zoom)
    for key in ("removeserverpresetname", "removeserverpresetno"):
        if key in args:
            memory.presets.pop(_existing_preset(args, key, memory))
    for key in ("gotoserverpresetname", "gotoserverpresetno"):
        if key in args:
            preset = memory.presets[_existing_preset(args, key, memory)]
            head.absolute(now, preset.pan, preset.tilt, preset.zoom, speed=number(args, "speed"))


def _preset_to_set(args: Mapping[str, str], memory: CameraMemory) -> tuple[int, str]:
    if "setserverpresetname" in args:
        name = args["setserverpresetname"]
        if not 1 <= len(name) <= 31 or not name.isprintable():
            raise BadArgument(f'setserverpresetname: invalid value "{name}"')
        no = memory.number_of(name) or next(n for n in range(1, 1000) if n not in memory.presets)
        return no, name
    no = _preset_number(args["setserverpresetno"], "setserverpresetno")
    existing = memory.presets.get(no)
    return no, existing.name if existing else f"Preset {no}"


def _existing_preset(args: Mapping[str, str], key: str, memory: CameraMemory) -> int:
    value = args[key]
    no = memory.number_of(value) if key.endswith("name") else _preset_number(value, key)
    if no is None or no not in memory.presets:
        raise BadArgument(f'{key}: invalid value "{value}"')
    return no


def _preset_number(value: str, key: str) -> int:
    if not value.isdigit() or not 1 <= int(value) <= 999:
        raise BadArgument(f'{key}: invalid value "{value}"')
    return int(value)


def _move(args: Mapping[str, str], head: PtzHead, memory: CameraMemory, now: float) -> None:
    if "ircutfilter" in args:
        if args["ircutfilter"] not in ("on", "off", "auto"):
            raise BadArgument(f'ircutfilter: invalid value "{args["ircutfilter"]}"')
        head.set_ir_cut_filter(args["ircutfilter"])
    speed = number(args, "speed")
    if speed is not None and not 1 <= speed <= 100:
        raise BadArgument(f'speed: invalid value "{args["speed"]}"')
    pan, tilt, zoom = (number(args, k) for k in ("pan", "tilt", "zoom"))
    rpan, rtilt, rzoom = (number(args, k) for k in ("rpan", "rtilt", "rzoom"))
    if (pan, tilt, zoom) != (None, None, None):
        head.absolute(now, pan, tilt, zoom, speed=speed)
    if (rpan, rtilt, rzoom) != (None, None, None):
        head.relative(now, rpan or 0.0, rtilt or 0.0, rzoom or 0.0, speed=speed)
    if "continuouspantiltmove" in args:
        pan_pct, tilt_pct = _pair(args["continuouspantiltmove"])
        head.continuous(now, pan_pct, tilt_pct)
    if "continuouszoommove" in args:
        head.continuous(now, zoom_pct=_percent(args["continuouszoommove"],
                                               "continuouszoommove"))
    if "move" in args:
        _named_move(args["move"], head, memory, now, speed)


def _named_move(where: str, head: PtzHead, memory: CameraMemory, now: float,
                speed: float | None) -> None:
    if where == "home":
        home = memory.presets.get(1, HOME)
        head.absolute(now, home.pan, home.tilt, home.zoom, speed=speed)
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
