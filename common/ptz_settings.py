"""The PTZ service's lab-file section (`[ptz]`): which camera an instance drives, and how it
follows the robot. In `common/` because `stb deploy render` checks the whole section that
the compose file it writes will run, and no service imports another (docs/architecture.md)."""

from __future__ import annotations

from pydantic import Field, model_validator

from common.lab_views import PAPER_MARKER_MM, CameraConnection, default_cameras
from common.settings import NAME_PATTERN, ServiceSettings


class PtzSettings(ServiceSettings):
    """One instance per camera: ``stb ptz --instance ptz2`` drives ``cameras.ptz2``."""

    section = "ptz"

    instance: str = Field("ptz1", pattern=NAME_PATTERN)
    cameras: dict[str, CameraConnection] = Field(default_factory=default_cameras)
    timeout_s: float = Field(1.0, gt=0, description="every HTTP request to the camera")
    command_hz: float = Field(10.0, gt=0, le=30, description="at most this many moves a second")
    deadband_deg: float = Field(0.3, ge=0, description="smaller corrections are not sent")
    latency_s: float = Field(0.25, ge=0, le=1.0,
                             description="aim this far ahead: command latency plus motion")
    state_hz: float = Field(5.0, gt=0, le=20, description="position queries and state messages")
    zoom: int = Field(1, ge=1, le=9999, description="fixed zoom step (1 = wide, 3.8 mm)")
    target_size_mm: float | None = Field(
        None, gt=0, description="if set: zoom so that this size fills image_fraction")
    image_fraction: float = Field(0.3, gt=0, le=1)
    speed: int = Field(100, ge=1, le=100, description="VAPIX pan/tilt speed")
    manual_pause_s: float = Field(30.0, ge=0, description="a move that did not come from this "
                                  "service pauses following this long (status manual), longer "
                                  "while the camera keeps moving; 0 = never pause")
    manual_deg: float = Field(5.0, gt=0, description="a camera this far off the path of our "
                              "commands was moved by someone else")
    pointing_tolerance_deg: float = Field(
        3.0, gt=0, le=90, description="the pointing check (docs/operator.md): a preview whose "
        "robot marker is farther than this from where the pose puts it disagrees")
    robot_marker_mm: float = Field(PAPER_MARKER_MM, gt=0, le=200, description="the robot marker's "
                                   "diameter (a standard 19 mm mocap marker)")
    pointing_min_marker_px: float = Field(
        1.4, ge=0, le=100, description="a preview in which the robot marker would appear "
        "smaller than this (radius) is not judged: the detector's filters (area ≥ 3 px, "
        "roundness < 1.21) do not find it there (docs/operator.md)")
    pointing_persist: int = Field(2, ge=1, le=100, description="this many disagreeing previews "
                                  "in a row degrade the service's status")
    pointing_infrared_s: float = Field(
        300.0, ge=0, description="a preview in infrared (IR-cut filter off for one snapshot: "
        "the markers bright) this often for the pointing check, and at once for a new pose or "
        "a camera back; each is a mechanical switch, seen in the video; 0 = never (then it "
        "judges only previews that show markers anyway)")
    pointing_confirm_s: float = Field(
        2.0, gt=0, description="the next infrared preview this soon while the latest one "
        "disagreed with the pose (a wrong pose reported within seconds, and its end seen)")
    pointing_infrared_while_recording: bool = Field(
        False, description="infrared previews while a recording runs (stb record, the "
        "page's); off: the filter is left alone then, and the pointing check waits")
    preview_hz: float = Field(2.0, ge=0, le=5, description="preview snapshots a second while "
                              "following (stb/ptz/{camera}/preview); 0 = none")
    calibration_snapshot_hz: float = Field(10.0, gt=0, le=30,
                                           description="snapshots a second in calibration mode")
    calibration_max_markers: int = Field(8, ge=1, le=256, description="more bright round "
                                         "spots than this in a snapshot → too_many")

    @model_validator(mode="after")
    def _instance_has_a_camera(self) -> PtzSettings:
        if self.instance not in self.cameras:
            raise ValueError(f"instance {self.instance!r} has no entry in cameras "
                             f"(known: {', '.join(self.cameras) or 'none'})")
        return self

    def connection(self) -> CameraConnection:
        return self.cameras[self.instance]
