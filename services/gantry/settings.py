"""Gantry settings: the crane controller, the tracking camera, the algorithm, the limits."""

from __future__ import annotations

from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field, ValidationInfo, field_validator, model_validator

from common.crane_frame import CraneConnection
from common.lab_paths import DEFAULT_HEIGHT_MAP
from common.names import AlgorithmName
from common.settings import ServiceSettings, above_its_minimum
from common.tracking_camera import TrackingCameraModel
from services.gantry.kalman import FollowOptions
from services.gantry.predict import ParticleOptions

_PF = ParticleOptions()
_KF = FollowOptions()


class ParticleFilterSettings(BaseModel):
    """One of the paper's particle filters (eq. 11–12): its own parameters, which the paper
    does not give (docs/experiments.md: identified with the sim)."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    particles: int = Field(_PF.particles, ge=10, le=100_000)
    velocity_noise_mm_s: float = Field(_PF.velocity_noise_mm_s, gt=0, le=10_000,
                                       description="eq. 11's v_n (standard deviation)")
    diff_max_mm: float = Field(_PF.diff_max_mm, gt=0, le=100_000, description="eq. 12")

    def options(self) -> ParticleOptions:
        return ParticleOptions(**self.model_dump())


class DefaultFilterSettings(BaseModel):
    """``default``'s filter (ours: an IMM of calm to agile motion models with the gait's
    sway, ``services/gantry/kalman.py``, docs/experiments.md). The defaults suit every robot
    of the sim; a lab may set them for its own robot and compare with
    ``stb experiment gantry --lab FILE``."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    measurement_noise_mm: float = Field(
        _KF.measurement_noise_mm, gt=0, le=1000,
        description="how far a located position may be off with the crane at rest (a moving "
        "crane adds its speed times report_spread_s)")
    accels_mm_s2: tuple[float, ...] = Field(
        _KF.accels_mm_s2, min_length=1, max_length=5,
        description="the motion models' acceleration noise, calm (a walk: its sway goes to "
        "the gait) to agile (a slide, a corner)")
    bursts_s: tuple[float, ...] = Field(
        _KF.bursts_s, min_length=1, max_length=5,
        description="for each model, how long a speed lasts (0: it goes on): an agile model "
        "whose speed comes in bursts does not carry a slide on past its end")
    stay: float = Field(_KF.stay, gt=0.5, lt=1,
                        description="chance a model stays in charge from one period to the next")
    sway_drift_mm_s: float = Field(_KF.sway_drift_mm_s, ge=0, le=1000,
                                   description="how fast the gait's sway may change")

    @field_validator("accels_mm_s2")
    @classmethod
    def _positive(cls, accels: tuple[float, ...]) -> tuple[float, ...]:
        if any(not 0 < a <= 100_000 for a in accels):
            raise ValueError("each must be in (0, 100000] mm/s²")
        return accels

    @model_validator(mode="after")
    def _a_burst_per_model(self) -> DefaultFilterSettings:
        if len(self.bursts_s) != len(self.accels_mm_s2) or any(
                not 0 <= b <= 60 for b in self.bursts_s):
            raise ValueError(f"bursts_s: one per model in accels_mm_s2 "
                             f"({len(self.accels_mm_s2)}), each 0…60 s")
        return self

    def options(self) -> FollowOptions:
        return FollowOptions(**self.model_dump())


class GantrySettings(ServiceSettings):
    section = "gantry"

    crane_host: str = "127.0.0.1"
    crane_port: int = Field(5020, ge=1, le=65535)
    crane_timeout_s: float = Field(0.3, gt=0, le=5)
    crane: CraneConnection = Field(CraneConnection(), description="the controller's register "
                                   "map and frame: [gantry.crane] (docs/devices.md, "
                                   "stb gantry commission)")
    tracking_camera: TrackingCameraModel = Field(
        TrackingCameraModel(), description="the tracking camera's lens and mount: "
        "[gantry.tracking_camera] (stb gantry commission)")
    frames: str = Field("bus", description='"bus": stb/gantry/camera/frame; or '
                        '"opencv:0" / "opencv:rtsp://..." for a camera on this host')
    algorithm: AlgorithmName = "default"
    control_hz: float = Field(4.0, gt=0, le=20, description="setpoints a second (crane: 4 Hz)")
    heartbeat_hz: float = Field(10.0, gt=0, le=100, description="crane watchdog heartbeat")
    poll_hz: float = Field(40.0, gt=0, le=200, description="reads of the crane's reported "
                           "position, to tick a fixed time after each new one")
    after_report_s: float | None = Field(
        None, ge=0, description="ticks this long after the controller reports its position; "
        "default: 0.075 s for the paper's algorithms (eq. 8 adds the picture's offset to that "
        "report), 0.05 s before the controller takes the setpoint for default (it pairs each "
        "picture with the crane's position when it was taken)")
    target_check_mm: float = Field(5.0, ge=0, description="the crane's target must be within "
                                   "this of a setpoint the gantry wrote, or it stops the crane "
                                   "(another Modbus client writes setpoints); 0: no check")
    stale_after_s: float = Field(0.5, gt=0, le=5, description="older estimate → hold "
                                 "(as old as the bus lets a sample be: bus.max_age_s)")
    reaction_s: float = Field(0.114, ge=0, le=3, description="from the controller taking a "
                              "setpoint to the crane following it (stb gantry identify)")
    report_age_s: float = Field(0.05, ge=0, le=2, description="how old the position the "
                                "controller reports is when it reports it (stb gantry identify)")
    report_spread_s: float = Field(0.0225, ge=0, le=1, description="how much that age varies "
                                   "(standard deviation): a moving crane's position at a "
                                   "moment is that uncertain times its speed "
                                   "(stb gantry identify)")
    max_horizon_s: float = Field(1.0, gt=0, le=3, description="never extrapolate further")
    height_map: Path = Field(DEFAULT_HEIGHT_MAP, description="laser scan (.npz)")
    marker_height_mm: float = Field(80.0, ge=0, description="marker above the ground")
    x_min_mm: float = -3000.0
    x_max_mm: float = 3000.0
    y_min_mm: float = -3000.0
    y_max_mm: float = 3000.0
    workspace_margin_mm: float = Field(50.0, ge=0)
    max_speed_mm_s: float = Field(520.0, gt=0, description="setpoint motion limit: the "
                                  "crane's (stb gantry identify)")
    max_accel_mm_s2: float = Field(2080.0, gt=0)
    marker_gate_mm: float = Field(300.0, ge=0, description="a spot farther than this from "
                                  "where the robot should be is not it (0: no gate)")
    reacquire_after_s: float = Field(1.0, gt=0, le=60, description="marker lost this long: "
                                     "go to the motion capture's fix of the robot, if fresh")
    reacquire_speed_mm_s: float = Field(150.0, gt=0, description="... at this speed at most")
    mocap_max_age_s: float = Field(0.5, gt=0, le=5, description="an older fix is not used")
    mocap_gate_mm: float = Field(500.0, ge=0, description="a spot farther than this from the "
                                 "motion capture's fresh fix is not the robot (0: no check)")
    crane_marker: str = Field("crane", max_length=64, description="the motion capture's label "
                              "of the marker on the crane's carriage, at its reported point")
    crane_check_mm: float = Field(100.0, ge=0, description="the crane's position through its "
                                  "frame and the crane marker must agree within this, or the "
                                  "gantry does not arm, and armed it stops (0: no check — only "
                                  "where no motion capture sees the crane)")
    fix_check_mm: float = Field(100.0, ge=0, description="the tracking camera's fix and the "
                                "motion capture's robot must agree within this, or the gantry "
                                "does not arm on it, and armed it does not use it (0: no "
                                "check)")
    check_window_s: float = Field(0.5, gt=0, le=10, description="a disagreement counts once "
                                  "it has lasted this long")
    command_per_s: float = Field(2.0, gt=0, le=100, description="commands a second taken "
                                 "from one sender after its burst; the rest are answered "
                                 "\"too many\" (a stop is always taken)")
    command_burst: int = Field(5, ge=1, le=1000, description="commands one sender may send "
                               "at once")
    command_delegates: list[str] = Field(["web"], max_length=16, description="bus identities "
                                         "that sign in their own users (the page): their "
                                         "commands are limited per user they name; any other "
                                         "identity's per identity, whatever name it writes")
    seed: int = 0
    pf_position: ParticleFilterSettings = Field(
        ParticleFilterSettings(), description="pf-position and pf-position-gauss")
    pf_velocity: ParticleFilterSettings = Field(ParticleFilterSettings(),
                                                description="pf-velocity")
    default_filter: DefaultFilterSettings = Field(DefaultFilterSettings(),
                                                  description="the default algorithm's filter")
    cable_length_mm: float = Field(2000.0, gt=0, description="gravity-offload cable")
    offload_warn_pct: float = Field(5.0, gt=0, le=100, description="warn above this sideways "
                                    "share of the cable's pull")

    _intervals = field_validator("x_max_mm", "y_max_mm")(above_its_minimum)

    @model_validator(mode="before")
    @classmethod
    def _moved_fields(cls, data: object) -> object:
        moved = {"focal_mm": "focal_mm", "pixel_mm": "pixel_mm", "ref_u": "principal_px",
                 "ref_v": "principal_px", "lens_height_mm": "height_mm"}
        found = sorted(set(moved) & set(data)) if isinstance(data, dict) else []
        if found:
            raise ValueError(f"{', '.join(found)}: the tracking camera's settings are in "
                             f"[gantry.tracking_camera] now ("
                             f"{', '.join(sorted({moved[f] for f in found}))}; "
                             "stb gantry commission measures them)")
        return data

    @field_validator("workspace_margin_mm")
    @classmethod
    def _margin_leaves_a_workspace(cls, margin: float, info: ValidationInfo) -> float:
        for axis in ("x", "y"):
            low, high = info.data.get(f"{axis}_min_mm"), info.data.get(f"{axis}_max_mm")
            if low is not None and high is not None and 2 * margin >= high - low:
                raise ValueError(f"leaves no workspace along {axis} ({low:g}…{high:g} mm)")
        return margin

    @field_validator("poll_hz")
    @classmethod
    def _poll_within_a_period(cls, poll_hz: float, info: ValidationInfo) -> float:
        control_hz = info.data.get("control_hz")
        if control_hz is not None and poll_hz < 2 * control_hz:
            raise ValueError(f"must be at least twice control_hz ({control_hz}): a new "
                             "report must be seen within a control period")
        return poll_hz

    @field_validator("after_report_s")
    @classmethod
    def _after_report_within_a_period(cls, after_s: float | None, info: ValidationInfo
                                      ) -> float | None:
        control_hz = info.data.get("control_hz")
        if after_s is not None and control_hz is not None and after_s >= 1 / control_hz:
            raise ValueError(f"must be shorter than a control period ({1 / control_hz:g} s)")
        return after_s
