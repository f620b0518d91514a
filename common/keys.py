"""Every key expression of the bus, each defined once and next to the model it carries.

Keys are relative to a configurable prefix (default ``stb``)::

    PTZ_STATE.key("stb", camera="ptz1")   # "stb/ptz/ptz1/state"   (publish)
    PTZ_STATE.pattern("stb")              # "stb/ptz/*/state"      (subscribe)
"""

from __future__ import annotations

import functools
import re
import string
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

from common import messages as m

M = TypeVar("M", bound=m.Message)

DEFAULT_PREFIX = "stb"
_CHUNK = re.compile(r"^[a-z0-9_.-]+$")
_PARAM_VALUE = re.compile(r"^[A-Za-z0-9_.-]+$")
MIB = 1024 * 1024


def check_prefix(prefix: str) -> str:
    """Return ``prefix`` if it is one or more lowercase chunks without wildcards, else raise."""
    if not prefix or not all(_CHUNK.match(chunk) for chunk in prefix.split("/")):
        raise ValueError(
            f"bad key prefix {prefix!r}: use lowercase chunks of a-z 0-9 _ . - separated by '/'"
        )
    return prefix


@functools.cache
def _params(path: str) -> tuple[str, ...]:
    return tuple(f for _, f, _, _ in string.Formatter().parse(path) if f)


@dataclass(frozen=True)
class Topic(Generic[M]):
    """A key expression template and the model of its payload.

    ``stream`` marks a periodic stream: subscribers get the latest value per key and samples
    older than the configured age are dropped before they reach control logic.
    """

    path: str
    model: type[M]
    description: str
    stream: bool = True
    max_payload_bytes: int = 64 * 1024

    @property
    def params(self) -> tuple[str, ...]:
        return _params(self.path)

    def key(self, prefix: str, **params: str) -> str:
        """The concrete key to publish on; every parameter is required."""
        if not params and not self.params:  # the common case, at up to QTM's full rate
            return f"{prefix}/{self.path}"
        if set(params) != set(self.params):
            raise ValueError(f"{self.path} needs parameters {self.params}, got {sorted(params)}")
        for name, value in params.items():
            if not _PARAM_VALUE.match(value):
                raise ValueError(f"bad {name} {value!r} for {self.path}: use A-Z a-z 0-9 _ . -")
        return f"{prefix}/{self.path.format(**params)}"

    def pattern(self, prefix: str, **params: str) -> str:
        """A key expression to subscribe to; parameters left out match any value."""
        filled = {name: params.get(name, "*") for name in self.params}
        return f"{prefix}/{self.path.format(**filled)}"

    def match(self, prefix: str, key: str) -> dict[str, str] | None:
        """The parameters of a concrete ``key`` if it belongs to this topic, else None."""
        found = _key_regex(prefix, self.path).fullmatch(key)
        return found.groupdict() if found else None


@functools.lru_cache(maxsize=256)
def _key_regex(prefix: str, path: str) -> re.Pattern[str]:
    regex = re.escape(f"{prefix}/{path}")
    for _, name, _, _ in string.Formatter().parse(path):
        if name:
            regex = regex.replace(re.escape("{" + name + "}"), f"(?P<{name}>[^/]+)")
    return re.compile(regex)


TRACKER_MARKERS = Topic("tracker/markers", m.MarkerFrame, "every mocap frame's 3-D markers",
                        max_payload_bytes=256 * 1024)
TRACKER_ROBOT = Topic("tracker/robot", m.RobotPosition, "robot marker position and velocity")
PTZ_STATE = Topic("ptz/{camera}/state", m.PtzState, "pan, tilt, zoom and aim error of a camera")
PTZ_DETECTIONS = Topic("ptz/{camera}/detections", m.MarkerDetections,
                       "markers detected in a PTZ snapshot (calibration mode)")
PTZ_CALIBRATION = Topic("ptz/{camera}/calibration", m.CalibrationMode,
                        "puts a camera into calibration mode (with a lease) or out of it",
                        stream=False)
PTZ_HAND = Topic("ptz/{camera}/hand", m.PtzHand,
                 "an operator holds, moves or releases a camera (the page)", stream=False)
PTZ_SNAPSHOT = Topic("ptz/{camera}/snapshot", m.CameraFrame,
                     "JPEG snapshots of a camera in calibration mode", max_payload_bytes=2 * MIB)
PTZ_PREVIEW = Topic("ptz/{camera}/preview", m.PtzPreview,
                    "a low-rate JPEG of a following camera, with the robot marker's pixel",
                    max_payload_bytes=2 * MIB)
CALIB_COLLECT = Topic("calib/{camera}/collect", m.CollectRequest,
                      "starts or cancels a passpoint collection", stream=False)
CALIB_PROGRESS = Topic("calib/{camera}/progress", m.CollectProgress,
                       "progress and outcome of a passpoint collection", stream=False)
CALIB_POSE = Topic("calib/{camera}/pose", m.CameraPose,
                   "calibrated camera pose; also answered as a queryable", stream=False)
GANTRY_FRAME = Topic("gantry/camera/frame", m.CameraFrame, "raw tracking-camera frames",
                     max_payload_bytes=8 * MIB)
GANTRY_DETECTIONS = Topic("gantry/detections", m.MarkerDetections,
                          "markers detected in a tracking-camera frame")
GANTRY_ESTIMATE = Topic("gantry/estimate", m.RobotEstimate, "filtered robot position")
GANTRY_SETPOINT = Topic("gantry/setpoint", m.CraneSetpoint,
                        "crane setpoints, 4 Hz; only the gantry service may put them")
GANTRY_STATE = Topic("gantry/state", m.CraneState, "crane position and the gantry's status")
GANTRY_OFFLOAD = Topic("gantry/offload", m.GravityOffload,
                       "gravity offload: vertical force lost and sideways pull of the cable")
GANTRY_COMMAND = Topic("gantry/command/by/{sender}", m.GantryCommand,
                       "arm, disarm, stop, reset: only operators may send them, each on the key "
                       "of its bus identity (the router lets it put there only); the gantry "
                       "limits and audits them by that identity", stream=False)
GANTRY_COMMAND_REPLY = Topic("gantry/command/reply", m.GantryCommandReply,
                             "the gantry's answer to each command", stream=False)
VIDEO = Topic("video/{camera}", m.CameraFrame,
              "a camera's video (JPEG, as the camera's VAPIX MJPEG sent it): the observation "
              "camera's bird's-eye view from `stb observation`; the PTZ cameras' as "
              "`stb record --video` takes them (on the bus when a recording is replayed)",
              max_payload_bytes=2 * MIB)
TRUTH_ROBOT = Topic("sim/truth/robot/{robot}", m.RobotTruth, "sim only: true robot marker")
TRUTH_CRANE = Topic("sim/truth/crane", m.CraneTruth, "sim only: true crane position")
TRUTH_PTZ = Topic("sim/truth/ptz/{camera}", m.PtzTruth, "sim only: true camera pan/tilt/zoom")
HEALTH = Topic("health/{service}/{instance}", m.ServiceHealth,
               "each service's health, 1 Hz", stream=False)

ALL_TOPICS: tuple[Topic[Any], ...] = (
    TRACKER_MARKERS, TRACKER_ROBOT, PTZ_STATE, PTZ_DETECTIONS, PTZ_CALIBRATION, PTZ_SNAPSHOT,
    PTZ_PREVIEW, PTZ_HAND,
    CALIB_COLLECT, CALIB_PROGRESS, CALIB_POSE, GANTRY_FRAME, GANTRY_DETECTIONS, GANTRY_ESTIMATE,
    GANTRY_SETPOINT, GANTRY_STATE, GANTRY_OFFLOAD, GANTRY_COMMAND, GANTRY_COMMAND_REPLY,
    VIDEO, TRUTH_ROBOT, TRUTH_CRANE, TRUTH_PTZ, HEALTH,
)

ALIVE = "alive/{service}/{instance}"
"""Liveliness tokens (no payload): present while the service runs and reaches the router."""


def alive_key(prefix: str, service: str, instance: str) -> str:
    return f"{prefix}/{ALIVE.format(service=service, instance=instance)}"


def alive_pattern(prefix: str) -> str:
    return f"{prefix}/alive/**"


RECORDING = "recording/{recorder}"
"""Liveliness tokens (no payload) held by each running recording (``stb record``, the page's
too): while one is there the PTZ cameras leave their IR-cut filter alone (the pointing check's
switch flickers in the video; ``[ptz] pointing_infrared_while_recording``). Apart from
``alive/``: a recording that ends is no service gone."""


def recording_key(prefix: str, recorder: str) -> str:
    return f"{prefix}/{RECORDING.format(recorder=recorder)}"


def recording_pattern(prefix: str) -> str:
    return f"{prefix}/recording/*"


def parse_alive(prefix: str, key: str) -> tuple[str, str] | None:
    """(service, instance) of a liveliness key, or None if it is not one."""
    parts = key.split("/")
    base = prefix.split("/")
    if len(parts) != len(base) + 3 or parts[: len(base)] != base or parts[len(base)] != "alive":
        return None
    return parts[-2], parts[-1]


def topic_for(prefix: str, key: str) -> Topic[Any] | None:
    """The topic a concrete key belongs to, or None."""
    return next((t for t in ALL_TOPICS if t.match(prefix, key) is not None), None)
