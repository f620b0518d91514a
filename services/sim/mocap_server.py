"""A Qualisys QTM real-time server (RT protocol 1.25, little-endian port) playing the scenario.

The unmodified ``qtm-rt`` client connects, reads the 3D labels and 6DOF bodies, and streams
``3d`` (labelled), ``3dnolabels`` (unidentified), ``6d`` (body position and rotation matrix)
and ``6deuler`` (position and Euler angles) frames at the configured rate, with noise, dropouts
(NaN markers, lost bodies as NaN) and the protocol's events; while not capturing it answers
with NoMoreData. Parameters it does not have (analog, force, image, calibration, skeleton, …)
are refused with an error packet.
Packet building is pure (top of the module); the asyncio server is at the bottom.
"""

from __future__ import annotations

import asyncio
import dataclasses
import logging
import struct
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from common.camera import euler_xyz_deg
from services.sim.bodies import BodyDefinition

log = logging.getLogger(__name__)

GREETING = "QTM RT Interface connected"  # the exact string the client ignores
NAN32 = struct.unpack("<f", b"\xff\xff\xff\xff")[0]  # QTM's "missing marker": all bits set


class PacketType(IntEnum):
    ERROR = 0
    COMMAND = 1
    XML = 2
    DATA = 3
    NO_MORE_DATA = 4
    EVENT = 6


class Event(IntEnum):
    CONNECTED = 1
    CONNECTION_CLOSED = 2
    CAPTURE_STARTED = 3
    CAPTURE_STOPPED = 4


COMPONENT_3D = 1
COMPONENT_3D_NO_LABELS = 2
COMPONENT_6D = 5
COMPONENT_6D_EULER = 6


def packet(kind: PacketType, body: bytes = b"") -> bytes:
    return struct.pack("<II", 8 + len(body), kind) + body


def text_packet(kind: PacketType, text: str) -> bytes:
    return packet(kind, text.encode() + b"\0")


def event_packet(event: Event) -> bytes:
    return packet(PacketType.EVENT, bytes([event]))


@dataclass(frozen=True)
class MocapFrame:
    """One frame: labelled markers in label order (NaN rows = missing) and unidentified ones."""

    number: int
    timestamp_us: int
    labelled: np.ndarray  # (L, 3)
    unlabelled: list[tuple[int, np.ndarray]]
    bodies: list[tuple[np.ndarray, np.ndarray] | None] = dataclasses.field(default_factory=list)
    """Per 6DOF body: (position of its origin, world-from-body rotation), None when lost."""


def data_packet(frame: MocapFrame, components: set[int]) -> bytes:
    parts = []
    if COMPONENT_3D in components:
        body = struct.pack("<Ihh", len(frame.labelled), 0, 0) + _labelled_bytes(frame.labelled)
        parts.append(struct.pack("<II", 8 + len(body), COMPONENT_3D) + body)
    if COMPONENT_3D_NO_LABELS in components:
        body = struct.pack("<Ihh", len(frame.unlabelled), 0, 0) + _unlabelled_bytes(
            frame.unlabelled)
        parts.append(struct.pack("<II", 8 + len(body), COMPONENT_3D_NO_LABELS) + body)
    for component in (COMPONENT_6D, COMPONENT_6D_EULER):
        if component in components:
            body = struct.pack("<Ihh", len(frame.bodies), 0, 0) + b"".join(
                _body_values(pose, component) for pose in frame.bodies)
            parts.append(struct.pack("<II", 8 + len(body), component) + body)
    header = struct.pack("<qII", frame.timestamp_us, frame.number, len(parts))
    return packet(PacketType.DATA, header + b"".join(parts))


_NO_LABEL = np.dtype([("xyz", "<f4", 3), ("id", "<i4")])


def _labelled_bytes(xyz: np.ndarray) -> bytes:
    """x, y, z per marker as float32, a lost marker's as QTM's NaN (all bits set); in one go,
    as the sim must keep up with 1000 frames a second."""
    values = np.ascontiguousarray(xyz, dtype="<f4").reshape(-1, 3)
    if np.isnan(values).any():
        values = values.copy()
        values.view("<u4")[np.isnan(values)] = 0xFFFFFFFF
    return values.tobytes()


def _unlabelled_bytes(markers: list[tuple[int, np.ndarray]]) -> bytes:
    """x, y, z (float32) and the id (int32) per unidentified marker."""
    values = np.empty(len(markers), _NO_LABEL)
    for row, (marker_id, xyz) in zip(values, markers, strict=True):
        row["xyz"], row["id"] = xyz, marker_id
    return values.tobytes()


def _body_values(pose: tuple[np.ndarray, np.ndarray] | None, component: int) -> bytes:
    """One body of a 6D component: position and the rotation matrix column by column (as QTM
    sends it: R11 R21 R31 R12 …), or position and Euler angles (degrees; R = Rx·Ry·Rz, QTM's
    default roll, pitch, yaw); all NaN when the body is lost."""
    count = 12 if component == COMPONENT_6D else 6
    if pose is None:
        return struct.pack(f"<{count}f", *([NAN32] * count))
    position, rotation = pose
    rest = rotation.T.ravel() if component == COMPONENT_6D else euler_xyz_deg(rotation)
    return struct.pack(f"<{count}f", *map(float, position), *map(float, rest))


PARAMETER_GROUPS = ("general", "3d", "6d")
NOT_AVAILABLE = ("analog", "force", "gazevector", "eyetracker", "image", "skeleton",
                 "skeleton:global", "calibration")


def parameters_xml(labels: list[str], frequency_hz: float,
                   bodies: Sequence[tuple[BodyDefinition, list[str]]] = (),
                   groups: tuple[str, ...] = PARAMETER_GROUPS) -> str:
    """The parameters of ``groups`` (general, 3d, 6d); each body with its points' labels."""
    parts = ["<QTM_Parameters_Ver_1.25>"]
    if "general" in groups:
        parts.append(f"<General><Frequency>{frequency_hz:g}</Frequency>"
                     "<Capture_Time>0</Capture_Time></General>")
    if "3d" in groups:
        label_xml = "".join(f"<Label><Name>{name}</Name><RGBColor>ff0000</RGBColor></Label>"
                            for name in labels)
        parts.append(f"<The_3D><AxisUpwards>+Z</AxisUpwards><Labels>{len(labels)}</Labels>"
                     f"{label_xml}</The_3D>")
    if "6d" in groups:
        parts.append(f"<The_6D><Bodies>{len(bodies)}</Bodies>"
                     + "".join(_body_xml(b, names) for b, names in bodies) + "</The_6D>")
    return "".join(parts) + "</QTM_Parameters_Ver_1.25>"


def _body_xml(body: BodyDefinition, names: list[str]) -> str:
    points = "".join(f'<Point X="{x:.6f}" Y="{y:.6f}" Z="{z:.6f}" Virtual="0" PhysicalId="0" '
                     f'Name="{name}"/>' for (x, y, z), name in zip(body.points_mm, names,
                                                                    strict=True))
    return (f"<Body><Name>{body.name}</Name><Enabled>true</Enabled>"
            '<Color R="255" G="0" B="0"/><MaximumResidual>10.000000</MaximumResidual>'
            "<MinimumMarkersInBody>3</MinimumMarkersInBody>"
            f"<Points>{points}</Points></Body>")


def parse_parameters_command(words: list[str]) -> tuple[str, ...] | str:
    """``getparameters <group...>`` → the groups to send, or an error for one it lacks."""
    asked = [w.lower() for w in words] or ["all"]
    groups: list[str] = []
    for name in asked:
        if name == "all":
            groups += PARAMETER_GROUPS
        elif name in PARAMETER_GROUPS:
            groups.append(name)
        elif name in NOT_AVAILABLE:
            return f"No {name} parameters available in this capture"
        else:
            return f"Parse error: unknown parameter {name}"
    return tuple(groups)


_COMPONENTS = {"3d": COMPONENT_3D, "3dnolabels": COMPONENT_3D_NO_LABELS, "6d": COMPONENT_6D,
               "6deuler": COMPONENT_6D_EULER}


def parse_stream_command(words: list[str], rate_hz: float) -> tuple[int, set[int]] | str:
    """``streamframes <frames> <components...>`` → (frame divisor, components) or an error."""
    if len(words) < 2:
        return "Missing frames argument"
    frames, names = words[0].lower(), [w.lower() for w in words[1:]]
    if frames == "allframes":
        divisor = 1
    elif frames.startswith("frequencydivisor:") and frames[17:].isdigit():
        divisor = max(1, int(frames[17:]))
    elif frames.startswith("frequency:") and frames[10:].replace(".", "", 1).isdigit():
        divisor = max(1, round(rate_hz / max(float(frames[10:]), 1e-9)))
    else:
        return f"Invalid frames argument: {words[0]}"
    unknown = [n for n in names if n not in _COMPONENTS]
    if unknown:
        return f"Component not supported by this simulator: {unknown[0]}"
    return divisor, {_COMPONENTS[n] for n in names}


# --- the server ----------------------------------------------------------------------------------


@dataclass
class MocapSource:
    """What the server streams: labels, and the frame at a frame number."""

    labels: list[str]
    rate_hz: float
    frame_at: Callable[[int], MocapFrame]
    clock: Callable[[], float]  # seconds since the capture started
    bodies: list[tuple[BodyDefinition, list[str]]] = dataclasses.field(default_factory=list)
    """The 6DOF bodies, each with its points' labels, in the order frames carry them."""

    def frame_now(self) -> int:
        """The frame number the capture is at."""
        return int(self.clock() * self.rate_hz)


_CONTROL_REPLIES = {
    "takecontrol": "You are now master",
    "releasecontrol": "You are now a regular client",
    "new": "Creating new connection",
    "close": "Closing connection",
}


class MocapServer:
    """Serves ``source``; capturing from the start unless ``capturing=False``. A client that
    took control can ``stop`` and ``start`` the capture (events go to every client)."""

    def __init__(self, source: MocapSource, host: str = "127.0.0.1", port: int = 22223,
                 *, capturing: bool = True) -> None:
        self.source, self.host, self.port = source, host, port
        self.capturing = capturing
        self._server: asyncio.base_events.Server | None = None
        self._clients: set[asyncio.StreamWriter] = set()
        self._master: asyncio.StreamWriter | None = None
        self.sent: deque[tuple[int, float]] = deque(maxlen=100_000)
        """(frame number, wall time just before it was written to a client): when frames left
        the sim, for latency figures."""

    async def start(self) -> None:
        self._server = await asyncio.start_server(self._serve, self.host, self.port)
        self.port = self._server.sockets[0].getsockname()[1]
        log.info("QTM RT server on %s:%d (%g Hz)", self.host, self.port, self.source.rate_hz)

    async def close(self) -> None:
        if self._server is not None:
            self._server.close()
            for writer in list(self._clients):
                writer.close()
            await self._server.wait_closed()

    def broadcast(self, event: Event) -> None:
        for writer in list(self._clients):
            writer.write(event_packet(event))

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self._clients.add(writer)
        writer.transport.get_extra_info("socket").setsockopt(6, 1, 1)  # TCP_NODELAY
        writer.write(text_packet(PacketType.COMMAND, GREETING))
        streamer: asyncio.Task | None = None
        try:
            while True:
                header = await reader.readexactly(8)
                size, kind = struct.unpack("<II", header)
                if not 8 <= size <= 65536:
                    log.warning("QTM client sent a bad packet size %d; closing", size)
                    return
                body = (await reader.readexactly(size - 8)).rstrip(b"\0").decode(errors="replace")
                if kind != PacketType.COMMAND:
                    writer.write(text_packet(PacketType.ERROR, "Expected a command packet"))
                    continue
                words = body.split()
                verb = [w.lower() for w in words[:2]]  # QTM's commands ignore case
                if verb == ["streamframes", "stop"]:
                    _cancel(streamer)
                    streamer = None
                elif verb[:1] == ["streamframes"]:
                    parsed = parse_stream_command(words[1:], self.source.rate_hz)
                    if isinstance(parsed, str):
                        writer.write(text_packet(PacketType.ERROR, parsed))
                    else:
                        _cancel(streamer)
                        streamer = asyncio.create_task(self._stream(writer, *parsed))
                else:
                    writer.write(self._reply(words, writer))
                await writer.drain()
        except (asyncio.IncompleteReadError, ConnectionError):
            pass
        except asyncio.CancelledError:
            # The sim is stopping with a client connected. Ending the task normally keeps
            # asyncio's stream callback (Python 3.11) from logging the cancellation as an error.
            pass
        finally:
            _cancel(streamer)
            self._clients.discard(writer)
            if self._master is writer:
                self._master = None
            writer.close()

    def _reply(self, words: list[str], writer: asyncio.StreamWriter) -> bytes:
        command = words[0].lower() if words else ""
        src = self.source
        if command in _CONTROL_REPLIES or command in ("start", "stop"):
            return self._control(command, writer)
        if command == "version":
            version = words[1] if len(words) > 1 else "1.25"
            return text_packet(PacketType.COMMAND, f"Version set to {version}")
        if command == "qtmversion":
            return text_packet(PacketType.COMMAND, "QTM Version is 2024.1 (build 9000) [STB sim]")
        if command == "byteorder":
            return text_packet(PacketType.COMMAND, "Byte order is little endian")
        if command == "getstate":
            return event_packet(Event.CAPTURE_STARTED if self.capturing
                                else Event.CAPTURE_STOPPED)
        if command == "getparameters":
            groups = parse_parameters_command(words[1:])
            if isinstance(groups, str):
                return text_packet(PacketType.ERROR, groups)
            return text_packet(PacketType.XML, parameters_xml(src.labels, src.rate_hz,
                                                              src.bodies, groups))
        if command == "getcurrentframe":
            if not self.capturing:
                return packet(PacketType.NO_MORE_DATA)
            parsed = parse_stream_command(["allframes", *words[1:]], src.rate_hz)
            if isinstance(parsed, str):
                return text_packet(PacketType.ERROR, parsed)
            return data_packet(src.frame_at(src.frame_now()), parsed[1])
        return text_packet(PacketType.ERROR, f"Command not supported by this simulator: {command}")

    def _control(self, command: str, writer: asyncio.StreamWriter) -> bytes:
        if command == "takecontrol":
            if self._master not in (None, writer):
                return text_packet(PacketType.ERROR, "Another client is master")
            self._master = writer
        elif command == "releasecontrol" and self._master is writer:
            self._master = None
        elif command in ("start", "stop", "new", "close") and self._master is not writer:
            return text_packet(PacketType.ERROR, "You must be master to issue this command")
        if command in ("start", "stop"):
            self.capturing = command == "start"
            self.broadcast(Event.CAPTURE_STARTED if self.capturing else Event.CAPTURE_STOPPED)
            reply = "Starting measurement" if self.capturing else "Stopping measurement"
            return text_packet(PacketType.COMMAND, reply)
        return text_packet(PacketType.COMMAND, _CONTROL_REPLIES[command])

    async def _stream(self, writer: asyncio.StreamWriter, divisor: int,
                      components: set[int]) -> None:
        """Send every ``divisor``-th frame as the capture reaches it (catching up after a
        late wake-up, at most a tenth of a second's worth at once)."""
        src = self.source
        period = divisor / src.rate_hz
        burst = max(1, int(0.1 * src.rate_hz / divisor))
        last: int | None = None
        idle_since: float | None = None
        loop = asyncio.get_running_loop()
        while not writer.is_closing():
            if not self.capturing:
                # NoMoreData at once, then once a second, until the capture starts again.
                if idle_since is None or loop.time() - idle_since >= 1.0:
                    writer.write(packet(PacketType.NO_MORE_DATA))
                    idle_since = loop.time()
                last = None
                await asyncio.sleep(0.05)
                continue
            idle_since = None
            newest = src.frame_now() // divisor * divisor
            first = newest if last is None else max(last + divisor, newest - burst * divisor)
            for number in range(first, newest + 1, divisor):
                data = data_packet(src.frame_at(number), components)
                leaving = time.time()  # before the write: the reader may run before it returns
                writer.write(data)
                self.sent.append((number, leaving))
            last = newest
            if writer.transport.get_write_buffer_size() > 4 * 1024 * 1024:
                log.warning("QTM client is not reading; closing its connection")
                writer.close()
                return
            # Wake when the next frame is due (as QTM sends a frame when it is captured).
            due = (newest + divisor) / src.rate_hz - src.clock()
            await asyncio.sleep(min(max(due, 0.0005), period))


def _cancel(task: asyncio.Task | None) -> None:
    if task is not None:
        task.cancel()
