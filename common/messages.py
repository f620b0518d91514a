"""Every message that crosses the bus: one frozen pydantic model per key expression.

Conventions (see docs/wire-format.md, which is generated from this module):

* units are in field names: ``_mm``, ``_deg``, ``_px``, ``_s``, ``_mm_s``;
* world frame: x, y horizontal, z up, millimetres (the mocap's frame);
* every message carries ``measured_s`` (when the value was *measured*, UNIX seconds, wall clock)
  and ``sent_s`` (when it was published; filled in by the bus, so producers leave it at 0);
* decoding is strict: no extra or missing fields, no NaN or infinity, no silent type coercion.
  Missing data is left out (an absent marker), never sent as NaN.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from common.data_sheet import AXIS_215_PX_PER_MM
from common.names import AlgorithmName, GantryCommandName, GantryMode
from common.pose_fields import PoseFields

NAME_CHARS, WHO_CHARS, TEXT_CHARS = 64, 128, 500
Name = Annotated[str, Field(min_length=1, max_length=NAME_CHARS, pattern=r"^[A-Za-z0-9_.-]+$")]
"""A camera's, a service's, a body's name: what a key expression may hold."""
Who = Annotated[str, Field(max_length=WHO_CHARS)]
"""Who sent or holds something: a user or an operator's name, with where from."""
Text = Annotated[str, Field(max_length=TEXT_CHARS)]
"""Why: a reason, a refusal's detail, a status's explanation, for people to read."""


def who(text: str) -> str:
    """``text`` cut to what a ``Who`` field holds (a producer's own, long, name)."""
    return text[:WHO_CHARS]


def text(words: str) -> str:
    """``words`` cut to what a ``Text`` field holds."""
    return words[:TEXT_CHARS]


def name(words: str) -> str:
    """``words`` cut to a ``Name``'s length (its pattern is the sender's to meet)."""
    return words[:NAME_CHARS]


class Message(BaseModel):
    """Base of every bus message: frozen, strict, finite, with its two time stamps."""

    model_config = ConfigDict(frozen=True, extra="forbid", strict=True, allow_inf_nan=False)

    measured_s: float = Field(description="time of measurement, UNIX seconds (wall clock)")
    sent_s: float = Field(0.0, description="time of publication, UNIX seconds; set by the bus")


# --- tracker ----------------------------------------------------------------------------------


class Marker(BaseModel):
    """One 3-D marker of a mocap frame, in the world frame."""

    model_config = Message.model_config

    label: str = Field("", max_length=64, description='QTM label; "" for an unlabelled marker')
    id: int = Field(0, ge=0, description="QTM id of an unlabelled marker; 0 for labelled ones")
    x_mm: float
    y_mm: float
    z_mm: float


class RigidBody(BaseModel):
    """One 6DOF body of a mocap frame (QTM's 6D): where its origin is and how it is turned."""

    model_config = Message.model_config

    name: str = Field(min_length=1, max_length=64, description="QTM's name of the body")
    x_mm: float
    y_mm: float
    z_mm: float
    qw: float = Field(ge=0, le=1, description="rotation, world from body, as a unit quaternion "
                      "(w, x, y, z) with w ≥ 0")
    qx: float = Field(ge=-1, le=1)
    qy: float = Field(ge=-1, le=1)
    qz: float = Field(ge=-1, le=1)


class MarkerFrame(Message):
    """All markers and 6DOF bodies seen in one mocap frame. Those the mocap lost are absent."""

    frame: int = Field(ge=0, description="mocap frame number")
    markers: list[Marker] = Field(max_length=1000)
    bodies: list[RigidBody] = Field(default_factory=list, max_length=100,
                                    description="6DOF bodies (only when the tracker streams them)")


class RobotPosition(Message):
    """The robot's position and velocity, in the world frame: its marker's, or — when the
    tracker is given a 6DOF body — the body's origin, with the body's orientation."""

    label: str = Field("", max_length=64, description='marker label; "" if picked by motion '
                       "or from a body")
    x_mm: float
    y_mm: float
    z_mm: float
    vx_mm_s: float
    vy_mm_s: float
    vz_mm_s: float
    body: str = Field("", max_length=64, description='the 6DOF body it comes from; "" for a '
                      "marker")
    qw: float | None = Field(None, ge=0, le=1, description="the body's rotation, world from "
                             "body, as a unit quaternion (w, x, y, z), w ≥ 0; None for a marker")
    qx: float | None = Field(None, ge=-1, le=1)
    qy: float | None = Field(None, ge=-1, le=1)
    qz: float | None = Field(None, ge=-1, le=1)


# --- marker detections (PTZ calibration mode and the gantry's tracking camera) ---------------


class DetectedMarker(BaseModel):
    """One bright round region found by the paper's detector (§2.1)."""

    model_config = Message.model_config

    u_px: float = Field(description="column of the centroid, 0 = left edge")
    v_px: float = Field(description="row of the centroid, 0 = top edge")
    radius_long_px: float = Field(ge=0)
    radius_short_px: float = Field(ge=0)
    angle_deg: float = Field(ge=-180, le=180, description="direction of the long axis")
    roundness: float = Field(ge=1, description="radius_long / radius_short")
    area_px: int = Field(ge=0)


class MarkerDetections(Message):
    """The detector's result for one camera image (``measured_s`` = capture time)."""

    camera: Name
    status: Literal["ok", "none", "too_many"]
    threshold: int = Field(ge=0, le=255, description="gray threshold finally used")
    width_px: int = Field(gt=0)
    height_px: int = Field(gt=0)
    markers: list[DetectedMarker] = Field(max_length=256)
    answered_after_s: float = Field(0.0, ge=0, le=60, description="how long the camera took "
                                    "to answer the snapshot request sent at ``measured_s``: "
                                    "the picture was taken within it (0: not known)")


# --- PTZ ----------------------------------------------------------------------------------------

PtzStatus = Literal["waiting_for_pose", "tracking", "idle", "calibrating", "camera_unreachable",
                    "manual", "held"]


def _focal_in_pixels(data: object) -> object:
    """A message written before focal lengths were pixels (a stored pose, a recording): its
    ``focal_mm`` was the AXIS 215's, whose model was the only one then (704 px over 3.6 mm)."""
    if isinstance(data, dict) and "focal_mm" in data and "focal_px" not in data:
        data = {k: v for k, v in data.items() if k != "focal_mm"} | {
            "focal_px": float(data["focal_mm"]) * AXIS_215_PX_PER_MM}
        if isinstance(data.get("lens"), list):
            data["lens"] = [_focal_in_pixels(at) for at in data["lens"]]
    return data


class PtzState(Message):
    """What a PTZ camera reports and how well it points at the robot."""

    camera: Name
    status: PtzStatus
    pan_deg: float = Field(ge=-180, le=180)
    tilt_deg: float = Field(ge=-90, le=90)
    zoom: int = Field(ge=1, le=19999, description="VAPIX zoom step, 1 = wide")
    focal_px: float = Field(gt=0, le=1e5, description="focal length for that zoom step, in "
                            "pixels of the camera's picture")
    aim_error_deg: float = Field(
        ge=0, description="angle between the optical axis and the robot; 0 if not tracking"
    )
    pointing_error_deg: float | None = Field(
        None, ge=0, description="measured in the latest preview: from where the pose puts the "
        "robot marker to the nearest marker found; None: not judged or no marker seen")
    pointing_problem: str = Field("", max_length=300, description="why the pointing is not to "
                                  "be trusted (previews disagreeing in a row); empty: fine")
    held_by: Who = Field("", description="the operator who holds the camera "
                         "(status held: it does not follow until released); empty: nobody")
    presets: list[str] = Field(default_factory=list, max_length=64,
                               description="the camera's own preset positions, by name")

    _written_in_mm = model_validator(mode="before")(_focal_in_pixels)


HandAction = Literal["hold", "move", "nudge", "preset", "follow"]


class PtzHand(Message):
    """An operator's hand on a PTZ camera: hold it (it stops following), move it (to a pan,
    tilt and zoom, or by them from where it is: nudge), send it to one of its presets, or let
    it follow the robot again. Only operator and web identities may send it
    (deploy/zenoh/router.json5)."""

    camera: Name
    action: HandAction
    pan_deg: float | None = Field(None, ge=-180, le=180, description="move: where to; nudge: "
                                  "by how much")
    tilt_deg: float | None = Field(None, ge=-180, le=180, description="move (−90…90): where "
                                   "to; nudge: by how much")
    zoom: int | None = Field(None, ge=-19999, le=19999, description="move (1…19999): the "
                             "VAPIX zoom step; nudge: by how many steps")
    preset: str = Field("", max_length=64, description="preset: its name")
    operator: Who = Field(description="who (from the page: 'user (web "
                          "address)')")

    @model_validator(mode="after")
    def _a_move_is_a_position(self) -> PtzHand:
        if self.action == "move" and ((self.tilt_deg is not None and abs(self.tilt_deg) > 90)
                                      or (self.zoom is not None and self.zoom < 1)):
            raise ValueError("move: tilt_deg within ±90 and zoom at least 1")
        return self


# --- calibration --------------------------------------------------------------------------------


class LensAtZoom(BaseModel):
    """The lens as a multi-zoom calibration measured it at one zoom step."""

    model_config = Message.model_config

    zoom: int = Field(ge=1, le=19999)
    focal_px: float = Field(gt=0, le=1e5, description="in pixels of the pose's picture")
    distortion: list[float] = Field(min_length=5, max_length=5, description="OpenCV's k1, k2, "
                                    "p1, p2, k3 on normalised image coordinates")
    passpoints: int = Field(ge=0, description="inliers at this zoom")
    mean_error_px: float = Field(ge=0, description="mean reprojection error at this zoom")

    _written_in_mm = model_validator(mode="before")(_focal_in_pixels)


class CameraPose(PoseFields, Message):
    """A camera's calibrated pose T_world_camera (paper eq. 1: R = Rx·Ry·Rz; x = optical axis;
    its six fields: common/pose_fields.py)."""

    camera: Name
    focal_px: float = Field(gt=0, le=1e5, description="focal length the pose was fitted with, "
                            "in pixels of its picture")
    width_px: int = Field(704, gt=0, le=8192, description="the picture the pose and the lens "
                          "were measured in (the AXIS 215's 704 × 576 by default)")
    height_px: int = Field(576, gt=0, le=8192)
    principal_u_px: float | None = Field(None, ge=0, le=8192, description="the lens's "
                                         "principal point as a multi-zoom calibration "
                                         "measured it; None: the picture's centre")
    principal_v_px: float | None = Field(None, ge=0, le=8192)
    mean_error_px: float = Field(ge=0, description="mean reprojection error over the inliers")
    passpoints: int = Field(ge=0, description="passpoints used (inliers)")
    time_offset_s: float = Field(0.0, description="mocap clock minus camera clock (add it to a "
                                 "snapshot's time to get the mocap time), if fitted")
    lens: list[LensAtZoom] = Field(default_factory=list, max_length=64, description="the "
                                   "lens measured at two or more zoom steps, by zoom; empty: "
                                   "calibrated at one zoom (the straight-line zoom curve of "
                                   "the AXIS 215's data sheet, no distortion)")
    version: int = Field(0, ge=0, le=2**53, description="the calibration service's count for "
                         "this camera: a newer pose has a higher version (or the same version, "
                         "measured later); a PTZ service takes a pose only from the calibration "
                         "service's answer, a message on the key is only news to ask again")

    _written_in_mm = model_validator(mode="before")(_focal_in_pixels)


class CalibrationMode(Message):
    """Asks a PTZ service to hold its camera still for passpoint collection (paper §2.1): IR cut
    filter off, pan/tilt/zoom fixed, snapshots detected and published. The mode ends when
    ``active`` is false or no request came for ``lease_s`` (a dead collector frees the camera)."""

    camera: Name
    active: bool
    pan_deg: float | None = Field(None, ge=-180, le=180, description="None: keep the current")
    tilt_deg: float | None = Field(None, ge=-90, le=90)
    zoom: int | None = Field(None, ge=1, le=19999)
    lease_s: float = Field(3.0, gt=0, le=60)


class CollectRequest(Message):
    """Asks the calib service to collect passpoints for a camera, then solve and publish; or
    cancels a collection, or accepts or discards a solved pose held for review."""

    camera: Name
    action: Literal["start", "cancel", "accept", "discard"] = "start"
    count: int = Field(100, ge=6, le=10_000, description="passpoints to collect (with "
                       "``zooms``: at the widest step)")
    step_count: int | None = Field(None, ge=6, le=10_000, description="with ``zooms``: "
                                   "passpoints at each step but the widest, at most ``count``; "
                                   "None: the calib service's ``step_count``")
    timeout_s: float = Field(600.0, gt=0, description="give up after this long")
    review: bool = Field(False, description="hold the solved pose (state review) until an "
                         "operator accepts or discards it; else it is taken at once")
    zooms: list[int] = Field(default_factory=list, max_length=16, description="zoom steps to "
                             "collect at (``count`` passpoints at the widest, ``step_count`` at "
                             "the others), for one fit of the pose "
                             "and the lens across the zoom range; empty: one zoom (the hold's)")

    @model_validator(mode="after")
    def _zooms_distinct(self) -> CollectRequest:
        if len(set(self.zooms)) != len(self.zooms) or any(not 1 <= z <= 19999
                                                          for z in self.zooms):
            raise ValueError(f"zooms must be distinct steps 1–19999, not {self.zooms}")
        if len(self.zooms) == 1:
            raise ValueError("one zoom is no zoom curve: name two or more, or none")
        return self


CollectState = Literal["collecting", "solving", "review", "done", "failed", "cancelled",
                       "discarded"]


class CollectProgress(Message):
    """How a passpoint collection goes; the last one of a run is done, failed, cancelled or
    discarded (``review``: solved, waiting for an operator's accept or discard)."""

    camera: Name
    state: CollectState
    passpoints: int = Field(ge=0)
    target: int = Field(ge=0)
    snapshots: int = Field(ge=0, description="snapshots seen so far")
    skipped: dict[str, int] = Field(description="snapshots not used, by reason")
    message: Text = ""
    mean_error_px: float | None = Field(None, ge=0, description="of the solved pose (review, "
                                        "done)")
    zoom: int | None = Field(None, ge=1, le=19999, description="the zoom step being collected "
                             "at, in a collection at several")
    zooms_done: int = Field(0, ge=0, description="zoom steps with all their passpoints")
    zooms: int = Field(0, ge=0, description="zoom steps to collect at (0: one, the hold's)")


class PtzPreview(Message):
    """A low-rate JPEG of what a following camera sees, for people to look at
    (``measured_s`` = capture time). ``markers``: bright round spots the detector found (few
    without the IR emitter); ``robot_px``: where the tracked robot marker should appear, from
    the camera's pose, its pan/tilt at capture and the robot's position then."""

    camera: Name
    seq: int = Field(ge=0)
    width_px: int = Field(gt=0, le=8192)
    height_px: int = Field(gt=0, le=8192)
    jpeg: bytes
    pan_deg: float = Field(ge=-180, le=180)
    tilt_deg: float = Field(ge=-90, le=90)
    markers: list[DetectedMarker] = Field(max_length=256)
    robot_px: list[float] | None = Field(
        None, min_length=2, max_length=2,
        description="[u, v] of the robot marker; None without a pose or a robot")
    robot_radius_px: float | None = Field(
        None, ge=0, le=8192, description="how large (radius) the robot marker should appear "
        "there; None with robot_px")


# --- gantry -------------------------------------------------------------------------------------


class CameraFrame(Message):
    """A raw tracking-camera image from a camera host (``measured_s`` = capture time)."""

    camera: Name
    seq: int = Field(ge=0, description="frame counter of the camera host")
    width_px: int = Field(gt=0, le=8192)
    height_px: int = Field(gt=0, le=8192)
    encoding: Literal["mono8", "jpeg"] = Field(description="mono8: row-major uint8 pixels")
    data: bytes


class RobotEstimate(Message):
    """The gantry's estimate of the robot marker (``measured_s`` = capture time of its frame)."""

    algorithm: AlgorithmName
    valid: bool = Field(description="False while the marker is lost")
    x_mm: float
    y_mm: float
    z_mm: float
    vx_mm_s: float
    vy_mm_s: float


class CraneSetpoint(Message):
    """Where the crane shall go. Only the gantry service may publish it."""

    seq: int = Field(ge=0, description="increases by one per setpoint of one gantry run")
    x_mm: float
    y_mm: float
    hold: bool = Field(description="True: stay where you are (no valid estimate)")


CraneStatus = Literal["idle", "tracking", "reacquiring", "holding", "stale", "fault", "stopped",
                      "unreachable"]




class CraneState(Message):
    """The crane as its controller reports it, and what the gantry service is doing."""

    status: CraneStatus
    x_mm: float
    y_mm: float
    target_x_mm: float
    target_y_mm: float
    enabled: bool
    moving: bool
    fault_bits: int = Field(ge=0, le=0xFFFF, description="controller fault register")
    safety_ok: bool = Field(True, description="the controller's safety circuit is closed")
    mode: GantryMode = Field("disarmed", description="disarmed: never moves the crane; "
                             "armed: tracks; stopped: latched until an operator's reset")
    mode_by: Who = Field("", description="who changed the mode last")
    mode_reason: Text = Field("", description="why")
    mode_since_s: float = Field(0.0, description="when, UNIX seconds")
    command: str = Field("", max_length=16, description="the last operator's command the "
                         "gantry answered (arm, disarm, stop, reset; empty: none yet)")
    command_by: Who = Field("", description="who sent it (a name; from the "
                            "page: 'user (web address)')")
    command_s: float = Field(0.0, description="when the gantry answered it, UNIX seconds")
    command_accepted: bool = Field(False, description="its answer")
    command_detail: Text = Field("", description="why refused, or what changed")


class GantryCommand(Message):
    """An operator's command to the gantry; only the operator and web identities may send
    it (deploy/zenoh/router.json5)."""

    command: GantryCommandName
    operator: Who = Field(description="who asks (a name; from the page: "
                          "'user (web address)')")
    reason: Text = ""
    id: str = Field(max_length=64, description="chosen by the sender; the reply repeats it")


class GantryCommandReply(Message):
    """What the gantry made of a command."""

    id: str = Field(max_length=64)
    command: GantryCommandName
    accepted: bool
    detail: Text = Field(description="why refused, or what changed")
    mode: GantryMode = Field(description="the gantry's mode after it")


class GravityOffload(Message):
    """How the crane-to-robot error tilts the offload cable (paper §4)."""

    horizontal_error_mm: float = Field(ge=0)
    cable_length_mm: float = Field(gt=0)
    vertical_loss_pct: float = Field(ge=0, le=100, description="vertical pull lost, 1 − cos θ")
    horizontal_share_pct: float = Field(ge=0, le=100, description="sideways pull, sin θ")
    warning: bool = Field(description="horizontal share above the configured limit")
    warn_above_pct: float = Field(5.0, gt=0, le=100, description="that limit, % (the gantry's "
                                  "offload_warn_pct)")


# --- simulation ground truth (tests and evaluation only) ----------------------------------------


class RobotTruth(Message):
    """Where the simulated robot marker really is."""

    robot: Name
    x_mm: float
    y_mm: float
    z_mm: float
    vx_mm_s: float
    vy_mm_s: float


class CraneTruth(Message):
    """Where the simulated crane really is."""

    x_mm: float
    y_mm: float
    vx_mm_s: float
    vy_mm_s: float


class PtzTruth(Message):
    """A simulated PTZ camera's real pan, tilt and zoom."""

    camera: Name
    pan_deg: float
    tilt_deg: float
    zoom: int = Field(ge=1, le=19999)


# --- health -------------------------------------------------------------------------------------


class KeyStats(BaseModel):
    """Traffic of one key expression as one service sees it."""

    model_config = Message.model_config

    received: int = Field(ge=0)
    published: int = Field(ge=0)
    dropped: dict[str, int] = Field(description="dropped samples by reason, e.g. not_msgpack")


HealthStatus = Literal["ok", "degraded", "stopping"]


class ServiceHealth(Message):
    """Published by every service once per second."""

    service: Name
    instance: Name
    host: str = Field(max_length=255)
    pid: int = Field(ge=0)
    started_s: float
    status: HealthStatus
    detail: Text = Field("", description="why degraded, if it is")
    keys: dict[str, KeyStats] = Field(description="per concrete key expression")
