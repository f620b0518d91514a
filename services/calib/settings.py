"""Calib settings: which cameras, where poses and passpoints are kept, how to collect."""

from __future__ import annotations

from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field

from common.settings import ServiceSettings


class Hold(BaseModel):
    """Where a camera is held while passpoints are collected (None: from the camera's home
    position, its home preset)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    pan_deg: float | None = Field(None, ge=-180, le=180)
    tilt_deg: float | None = Field(None, ge=-90, le=90)
    zoom: int | None = Field(None, ge=1, le=19999)


class CalibSettings(ServiceSettings):
    section = "calib"

    cameras: list[str] = Field(["ptz1", "ptz2"], description="cameras this service calibrates")
    data_dir: Path = Field(Path("run/calib"), description="poses, passpoints and images")
    collect_missing: bool = Field(False, description="at start, collect for every camera "
                                  "without a stored pose (the demo does)")
    marker_label: str = Field("wand", description='mocap label of the calibration marker; "" = '
                              "the unlabelled marker that moves")
    count: int = Field(100, ge=6, le=10_000, description="passpoints per collection (with "
                       "several zoom steps: at the widest)")
    step_count: int = Field(30, ge=6, le=10_000, description="with several zoom steps: "
                            "passpoints at each step but the widest, at most ``count`` (the "
                            "focal length there; the distortion is measured at the widest)")
    timeout_s: float = Field(600.0, gt=0, description="a collection gives up after this long")
    stall_s: float = Field(60.0, gt=0, description="a collection that gains no passpoint for "
                           "this long (from when the camera is held) fails, saying what the "
                           "snapshots showed")
    hold_wait_s: float = Field(15.0, gt=0, description="how long a collection waits for the "
                               "PTZ service to hold the camera (a busy PC) before it fails "
                               "naming that service")
    min_spacing_mm: float = Field(50.0, ge=0, description="a passpoint needs the marker this "
                                  "far from the previous one")
    min_spacing_px: float = Field(20.0, ge=0, le=200, description="a passpoint needs the "
                                  "marker this far in the picture from every one taken before "
                                  "at the same zoom: spread over the picture")
    hold: dict[str, Hold] = Field(default_factory=dict, description="per camera: pan, tilt, "
                                  "zoom during collection")
    fit_focal: bool = False
    inlier_px: float = Field(10.0, gt=0, description="passpoints farther than this from the "
                             "fit are rejected: pixels of a 704-wide picture, scaled with the "
                             "camera's (27 px at 1920)")
    max_time_offset_s: float = Field(0.5, ge=0, le=5)
    max_mean_error_px: float = Field(20.0, gt=0, description="a pose with a larger mean "
                                     "error is refused (scaled as inlier_px)")
    lease_s: float = Field(3.0, gt=0, le=60, description="calibration mode lease on a camera")
    review_s: float = Field(600.0, gt=0, le=86_400, description="a solved pose held for an "
                            "operator's review (from the page) is discarded after this long")
