"""Sim settings: the scenario, the crater, and each simulated device's address and behaviour.

The cameras' mount poses live here and nowhere else: no service reads them (the calibration
service has to find them), only the sim and its tests.
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator

from common.camera import Pose
from common.crane_frame import CraneFrame
from common.crane_registers import RegisterMap
from common.data_sheet import AXIS_215_CHIP_MM, AXIS_215_PICTURE_PX
from common.lab_paths import SIM_CRATER_FILE
from common.lens import NO_DISTORTION
from common.pose_fields import PoseFields
from common.ptz_lens import DATA_SHEET_MM, PtzLens, ZoomCurve
from common.settings import NAME_PATTERN, ServiceSettings, above_its_minimum
from common.tracking_camera import TrackingCameraModel
from services.sim.crane import CraneParams
from services.sim.crane_server import ESTOP_REGISTER
from services.sim.ptz import PtzHead
from services.sim.robots import Railway, Walk
from services.sim.scenarios import Scenario


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class MocapSettings(_Section):
    host: str = "127.0.0.1"
    port: int = Field(22223, ge=0, le=65535, description="QTM RT little-endian port")
    rate_hz: float = Field(100.0, ge=100, le=1000)
    noise_mm: float = Field(0.5, ge=0)
    dropout: float = Field(0.005, ge=0, le=1, description="chance a marker is lost in a frame")
    robot_label: str = Field("robot", description='label of the robot marker; "" = unlabelled')
    static_markers: int = Field(3, ge=0, le=20)
    ghost_markers: int = Field(1, ge=0, le=10, description="unidentified markers in 3dnolabels")
    robot_body: str = Field("robot", max_length=64, description="the robot's 6DOF body (its "
                            'marker and three more, streamed as 6d/6deuler); "" = none')
    wand_body: str = Field("wand", max_length=64, description='the wand\'s 6DOF body; "" = none')
    crane_label: str = Field("crane", max_length=64, description="a marker on the crane's "
                             "camera carriage, at the crane's reported point and the tracking "
                             'camera lens\'s height, as a lab would stick one there; "" = none')


class PtzCameraSettings(PoseFields, _Section):
    """A simulated PTZ camera: where it truly is (the pose fields, common/pose_fields.py),
    its VAPIX server, its head and its lens."""

    name: str = Field(pattern=NAME_PATTERN)
    host: str = "127.0.0.1"
    port: int = Field(ge=0, le=65535)
    user: str = "root"
    password: str = "pass"
    auth: Literal["digest", "basic", "none"] = "digest"
    latency_s: float = Field(0.12, ge=0)
    pan_speed_deg_s: float = Field(100.0, gt=0)
    tilt_speed_deg_s: float = Field(90.0, gt=0)
    mjpeg_fps: float = Field(2.0, gt=0, le=30, description="the MJPEG stream's frame rate "
                             "(mjpg/video.cgi) when the request names none")
    zoom_focal_mm: list[tuple[float, float]] = Field(
        default_factory=DATA_SHEET_MM.points, min_length=2,
        max_length=64, description="the lens's truth: [zoom step, focal length mm] points, "
        "interpolated monotonically (PCHIP); default the AXIS 215's 3.8–46 mm spread evenly "
        "over steps 1–9999")
    picture_px: tuple[int, int] = Field(
        AXIS_215_PICTURE_PX, description="its full picture, width and height in pixels "
        "(image.cgi's default; half and a quarter of it offered too); default the AXIS 215's "
        "704 × 576, a current PTZ camera's is 1920 × 1080")
    chip_mm: tuple[float, float] = Field(
        AXIS_215_CHIP_MM, description="the chip the focal lengths of zoom_focal_mm are on: its "
        "width and height in mm (with picture_px, the pixels' size and aspect)")
    principal_offset_px: tuple[float, float] = Field(
        (0.0, 0.0), description="the lens's principal point from the picture's centre, "
        "pixels (right, down); 0: centred")
    distortion: tuple[float, float, float, float, float] = Field(
        NO_DISTORTION, description="OpenCV's k1, k2, p1, p2, k3 at the shortest focal length")
    distortion_long: tuple[float, float, float, float, float] | None = Field(
        None, description="… at the longest focal length (linear in focal length between "
        "them); none: the same as at the shortest")

    tilt_axis_mm: tuple[float, float, float] = Field(
        (0.0, 0.0, 0.0), description="the head's truth: where its tilt axis passes, from the "
        "mount's point on the pan axis, in the panned head's frame (x along the view at tilt "
        "0, y right, z down); 0: the axes meet")
    optical_centre_mm: tuple[float, float, float] = Field(
        (0.0, 0.0, 0.0), description="… and the lens's optical centre from that point on the "
        "tilt axis, in the camera's frame (x along the view); 0: on both axes")

    @field_validator("tilt_axis_mm", "optical_centre_mm")
    @classmethod
    def _within_a_head(cls, offset: tuple[float, float, float]) -> tuple[float, float, float]:
        if max(abs(v) for v in offset) > 500.0:
            raise ValueError(f"{list(offset)}: a PTZ head's offsets are within 500 mm")
        return offset

    @field_validator("picture_px")
    @classmethod
    def _a_picture(cls, size: tuple[int, int]) -> tuple[int, int]:
        if not (16 <= size[0] <= 8192 and 16 <= size[1] <= 8192 and size[0] % 4 == 0
                and size[1] % 4 == 0):
            raise ValueError(f"{list(size)}: a picture is 16–8192 pixels wide and high, in "
                             "multiples of 4 (its half and quarter are offered too)")
        return size

    @field_validator("chip_mm")
    @classmethod
    def _a_chip(cls, chip: tuple[float, float]) -> tuple[float, float]:
        if not (0 < chip[0] <= 50 and 0 < chip[1] <= 50):
            raise ValueError(f"{list(chip)}: a chip's width and height are 0–50 mm")
        return chip

    def resolutions(self) -> dict[str, tuple[int, int]]:
        """The picture sizes its VAPIX server offers: the full picture first (the default),
        then its half and its quarter."""
        width, height = self.picture_px
        return {f"{width // k}x{height // k}": (width // k, height // k) for k in (1, 2, 4)}

    @field_validator("zoom_focal_mm")
    @classmethod
    def _a_zoom_curve(cls, points: list[tuple[float, float]]) -> list[tuple[float, float]]:
        ZoomCurve.of(points)  # raises, naming the points, when they do not make a curve
        return points

    def head(self) -> PtzHead:
        """The camera's true head, standing at home: its mount, lens, speeds and offsets."""
        return PtzHead(Pose.of(self), lens=self.lens(), latency_s=self.latency_s,
                       pan_speed_deg_s=self.pan_speed_deg_s,
                       tilt_speed_deg_s=self.tilt_speed_deg_s, tilt_axis_mm=self.tilt_axis_mm,
                       optical_centre_mm=self.optical_centre_mm)

    def lens(self) -> PtzLens:
        """The camera's true lens in pixels of its picture (only the sim knows it:
        calibration measures it), from its focal lengths in mm on its chip."""
        width, height = self.picture_px
        chip_w, chip_h = self.chip_mm
        curve = ZoomCurve.of(self.zoom_focal_mm).scaled(width / chip_w)
        bent = any(self.distortion) or any(self.distortion_long or ())
        dx, dy = self.principal_offset_px
        return PtzLens(curve, (curve.focals[0], curve.focals[-1]) if bent else (),
                       (self.distortion, self.distortion_long or self.distortion) if bent
                       else (), width, height, (height / chip_h) / (width / chip_w),
                       (width / 2 + dx, height / 2 + dy) if dx or dy else None)


def _default_cameras() -> list[PtzCameraSettings]:
    # Near the paper's estimate for its camera (Table 2), and a second one across the crater.
    return [
        PtzCameraSettings(name="ptz1", port=8081, x_mm=3550, y_mm=1090,
                          z_mm=2190, rx_deg=180, ry_deg=30, rz_deg=165),
        PtzCameraSettings(name="ptz2", port=8082, x_mm=-3300, y_mm=-1800,
                          z_mm=2600, rx_deg=164, ry_deg=-27, rz_deg=-33),
    ]


_CRANE = CraneParams()


class CraneSettings(_Section, CraneFrame):
    """The simulated crane controller (``services/sim/crane.py``). The defaults are the crane
    identified against the paper's Tables 3–4 (docs/experiments.md).

    Its frame (``origin_mm``, ``yaw_deg``, ``flip_x``, ``flip_y``: ``common.crane_frame``) is
    the sim's truth of where the crane counts from: the workspace limits and everything on
    its Modbus registers are in the crane's own frame; what the sim shows of the world (the
    motion capture's ``crane`` marker, the truth topics, the tracking camera's pictures) is
    in the world's. The defaults are an ideal lab: the crane counts in the world's frame."""

    host: str = "127.0.0.1"
    port: int = Field(5020, ge=0, le=65535)
    x_min_mm: float = _CRANE.x_min_mm
    x_max_mm: float = _CRANE.x_max_mm
    y_min_mm: float = _CRANE.y_min_mm
    y_max_mm: float = _CRANE.y_max_mm
    max_speed_mm_s: float = Field(_CRANE.max_speed_mm_s, gt=0)
    max_accel_mm_s2: float = Field(_CRANE.max_accel_mm_s2, gt=0)
    cycle_s: float = Field(_CRANE.cycle_s, gt=0, le=2,
                           description="controller cycle: setpoints taken at 4 Hz")
    dead_time_s: float = Field(_CRANE.dead_time_s, ge=0, le=3,
                               description="a sampled setpoint becomes the target this later")
    position_time_constant_s: float = Field(
        _CRANE.position_time_constant_s, ge=0, le=3,
        description="the axes' position loop: distance / this = speed (0: flat out)")
    report_latency_s: float = Field(_CRANE.report_latency_s, ge=0, le=1,
                                    description="the reported position's age when published")
    report_jitter_s: float = Field(_CRANE.report_jitter_s, ge=0, le=1,
                                   description="spread (full width) of that age")
    watchdog_s: float = Field(_CRANE.watchdog_s, gt=0)
    registers: RegisterMap = Field(RegisterMap(), description="the register map it serves: "
                                   "the lab's [gantry.crane] (docs/devices.md)")
    estop_register: int = Field(ESTOP_REGISTER, ge=0, le=65535, description="the sim's own "
                                "e-stop button, a holding register: 1 pressed, 0 released")
    _intervals = field_validator("x_max_mm", "y_max_mm")(above_its_minimum)

    def params(self) -> CraneParams:
        return CraneParams(**self.model_dump(exclude={"host", "port", "registers",
                                                      "estop_register",
                                                      *CraneFrame.model_fields}))


class TrackingCameraSettings(_Section, TrackingCameraModel):
    """The crane's downward IR camera. Its lens and mount (``common.tracking_camera``: focal
    length, pixel pitch, principal point, OpenCV's distortion, yaw against the crane's axes,
    lens offset from the crane's reported point, height) are the sim's truth, which the gantry
    does not know: commissioning measures them (``stb gantry commission``). The defaults are
    an ideal camera: 8 mm lens, 7.5 µm pixels, 640 × 480, centred, no distortion, aligned,
    the lens at the crane's reported point 3.5 m up."""

    name: str = "tracking"
    rate_hz: float = Field(25.0, gt=0, le=120)
    delay_s: float = Field(0.04, ge=0, le=1, description="from the end of a frame's exposure "
                           "to its arrival at the gantry: readout, transfer, the bus")
    exposure_s: float = Field(0.004, ge=0, le=0.1, description="a moving marker smears over "
                              "it, and the picture is that much brighter (the camera's "
                              "exposure as the lab sets it: [camera] exposure_ms on a real one)")
    ground_gray_per_ms: float = Field(4.0, ge=0, le=1000, description="the crater's floor "
                                      "under the IR emitter, gray levels per ms of exposure")
    glint_gray_per_ms: float = Field(57.5, ge=0, le=10_000, description="a stray reflection's "
                                     "brightest point, gray levels per ms")
    marker_gray_per_ms: float = Field(1000.0, ge=0, le=100_000, description="the robot's "
                                      "retro-reflective marker, gray levels per ms (saturates)")
    noise: float = Field(2.5, ge=0, description="gray-level noise sigma")
    reflections_per_m2: float = Field(0.5, ge=0, le=20, description="stray reflections")

    def lens(self) -> TrackingCameraModel:
        """Only the lens and mount."""
        return TrackingCameraModel(**{name: getattr(self, name)
                                      for name in TrackingCameraModel.model_fields})


class ObservationCameraSettings(_Section):
    """The crane's colour observation camera beside the tracking camera (paper §3.1), served
    as an IP camera serves its pictures (VAPIX ``jpg/image.cgi``, ``mjpg/video.cgi``; 640x480
    or 320x240). The paper gives no figures for it: the defaults are a common 1/3-inch colour
    camera (4.8 × 3.6 mm chip) with a 6 mm lens, 150 mm beside the crane's reported point
    (about 2.8 × 2.1 m of ground below it). Nothing in the code models it (it is for people)."""

    enabled: bool = Field(True, description="serve it")
    name: str = Field("observation", pattern=NAME_PATTERN)
    host: str = "127.0.0.1"
    port: int = Field(8083, ge=0, le=65535)
    user: str = "root"
    password: str = "pass"
    auth: Literal["digest", "basic", "none"] = "digest"
    focal_mm: float = Field(6.0, gt=0, le=100)
    chip_mm: tuple[float, float] = Field((4.8, 3.6), description="the chip's width and height")
    offset_mm: tuple[float, float] = Field((150.0, 0.0), description="the lens from the "
                                           "crane's reported point, in the crane's frame (mm)")
    height_mm: float = Field(3450.0, gt=0, description="the lens above the world's z = 0")
    mjpeg_fps: float = Field(10.0, gt=0, le=30, description="the MJPEG stream's frame rate "
                             "when the request names none")
    jpeg_quality: int = Field(85, ge=10, le=100)

    @field_validator("chip_mm")
    @classmethod
    def _positive_chip(cls, chip: tuple[float, float]) -> tuple[float, float]:
        if min(chip) <= 0:
            raise ValueError("a chip's width and height are positive")
        return chip


_WALK, _RAIL = Walk(), Railway()


class WalkerSettings(_Section):
    """The walker scenario's robot (paper §3.3, Table 4); the defaults are identified."""

    speed_mm_s: float = Field(_WALK.speed_mm_s, gt=0, le=1000)
    step_hz: float = Field(_WALK.step_hz, gt=0, le=10, description="gait cycles per second")
    sway_mm: float = Field(_WALK.sway_mm, ge=0, le=500, description="sideways, amplitude")
    surge_mm: float = Field(_WALK.surge_mm, ge=0, le=500, description="forward and back, "
                            "amplitude (twice per gait cycle)")
    slide_per_s: float = Field(_WALK.slide_per_s, ge=0, le=10,
                               description="chance a second of slipping on steep ground")
    slide_speed_mm_s: float = Field(_WALK.slide_speed_mm_s, gt=0, le=3000,
                                    description="mean speed of a slide downhill (±20 %)")
    duration_s: float = Field(_WALK.duration_s, gt=0)

    def walk(self) -> Walk:
        return Walk(**self.model_dump())


class LocomotiveSettings(_Section):
    """The paper's model railway (§3.3, Table 3): an oval, five rounds at ~29 cm/s."""

    speed_mm_s: float = Field(_RAIL.speed_mm_s, gt=0, le=3000)
    rounds: int = Field(_RAIL.rounds, ge=1, le=100)
    straight_mm: float = Field(_RAIL.straight_mm, ge=0, le=6000)
    radius_mm: float = Field(_RAIL.radius_mm, gt=0, le=3000)

    def railway(self) -> Railway:
        return Railway(**self.model_dump())


class SimSettings(ServiceSettings):
    section = "sim"

    scenario: Scenario = Field("locomotive", description="parked: the robot stands still "
                               "(commissioning: stb gantry identify)")
    loop: bool = Field(True, description="start the scenario again when it ends")
    seed: int = 1
    crater_file: Path = Field(SIM_CRATER_FILE,
                              description="height map; generated from the seed if missing")
    truth_rate_hz: float = Field(20.0, gt=0, le=200)
    calibrate_first: list[str] = Field(
        default_factory=list, description="cameras to calibrate before the robot starts: the "
        "wand is carried through the view until each has a pose on stb/calib/{camera}/pose")
    wand_speed_mm_s: float = Field(600.0, gt=0, description="calibration wand between points")
    wand_dwell_s: float = Field(0.5, ge=0, description="calibration wand held still per point")
    bind: str | None = Field(None, description="if set, every device listens on this address "
                             "instead of its own host (e.g. 0.0.0.0 in a container)")
    targets: list[tuple[float, float, float]] = Field(
        default_factory=list, max_length=10, description="markers a lab stands below the crane "
        "for commissioning (stb gantry commission): [x, y, height above the ground] mm each, "
        "labelled target_1, target_2, … in the motion capture, seen by the tracking camera")
    mocap: MocapSettings = MocapSettings()
    cameras: list[PtzCameraSettings] = Field(default_factory=_default_cameras)
    crane: CraneSettings = CraneSettings()
    tracking_camera: TrackingCameraSettings = TrackingCameraSettings()
    observation_camera: ObservationCameraSettings = ObservationCameraSettings()
    walker: WalkerSettings = WalkerSettings()
    locomotive: LocomotiveSettings = LocomotiveSettings()

    def host_of(self, device_host: str) -> str:
        return self.bind or device_host
