"""Eq. 4 against hand-computed cases, its special cases, limits, and the round trip."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from common import messages as m
from common.camera import Pose
from common.ptz_lens import STRAIGHT_LINE, PtzLens, ZoomCurve, axis_215_px
from services.ptz.aim import (
    PtzLimits,
    aim_at,
    aim_error_deg,
    optical_axis,
    pan_tilt,
    predict,
    zoom_for_size,
)


@pytest.mark.parametrize(("target", "pan", "tilt"), [
    ((1, 1, 1), 45.0, -35.26439),          # the paper's Figure 7 example
    ((1, 0, 0), 0.0, 0.0),
    ((0, 1, 0), 90.0, 0.0),
    ((0, -1, 0), -90.0, 0.0),
    ((-1, 0, 0), 180.0, 0.0),              # straight behind: +180, never -180
    ((-1, -1e-12, 0), 180.0, 0.0),
    ((1, -1, 0), -45.0, 0.0),
    ((-1, -1, -math.sqrt(2)), -135.0, 45.0),
    ((3, 4, 0), math.degrees(math.atan2(4, 3)), 0.0),
])
def test_equation_4(target: tuple, pan: float, tilt: float) -> None:
    got_pan, got_tilt = pan_tilt(*target)
    assert got_pan == pytest.approx(pan, abs=1e-4) and got_tilt == pytest.approx(tilt, abs=1e-4)
    assert -180 < got_pan <= 180 and -90 <= got_tilt <= 90


def test_straight_down_or_up_keeps_the_current_pan() -> None:
    assert pan_tilt(0, 0, 5, current_pan_deg=33.0) == (33.0, -90.0)
    assert pan_tilt(0, 0, -5, current_pan_deg=-12.0) == (-12.0, 90.0)


def test_at_the_origin_nothing_moves() -> None:
    assert pan_tilt(0, 0, 0, current_pan_deg=3.0, current_tilt_deg=-4.0) == (3.0, -4.0)


def test_non_finite_target_is_refused() -> None:
    with pytest.raises(ValueError, match="not finite"):
        pan_tilt(float("nan"), 0, 0)


@pytest.mark.parametrize("pose", [Pose(3550, 1090, 2190, 180, 30, 165),   # standing
                                  Pose(-3300, -1800, 2600, 164, -27, -33),  # hanging
                                  Pose(0, 0, 3000, 180, 90, 0)])           # looking down
def test_aiming_puts_the_target_on_the_optical_axis(pose: Pose,
                                                    rng: np.random.Generator) -> None:
    for _ in range(50):
        target = rng.uniform([-2000, -2000, 0], [2000, 2000, 1500])
        pan, tilt = aim_at(target, pose, PtzLimits(-180, 180, -90, 90))
        assert aim_error_deg(target, pose, pan, tilt) < 1e-4  # acos resolution near 0°


def test_limits_clamp_the_command() -> None:
    pose = Pose(0, 0, 0, 0, 0, 0)
    assert aim_at(np.array([-1000.0, 10.0, 0.0]), pose) == (170.0, 0.0)
    assert aim_at(np.array([10.0, 0.0, 1000.0]), pose, PtzLimits(min_tilt=-20))[1] == -20.0


def test_optical_axis_inverts_equation_4(rng: np.random.Generator) -> None:
    for _ in range(50):
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        np.testing.assert_allclose(optical_axis(*pan_tilt(*direction)), direction, atol=1e-12)


def test_zoom_keeps_the_apparent_size() -> None:
    near = zoom_for_size(2000, object_mm=500, image_fraction=0.5)
    far = zoom_for_size(6000, object_mm=500, image_fraction=0.5)
    assert far > near
    # the object fills half the picture's height: 288 px = f_v · 500 / 6000
    assert PtzLens().intrinsics(far).fz_px == pytest.approx(0.5 * 576 * 6000 / 500, rel=1e-3)
    assert STRAIGHT_LINE.focal(far) == pytest.approx(axis_215_px(0.5 * 2.7 * 6000 / 500),
                                                     rel=1e-3)
    assert zoom_for_size(100, object_mm=500, image_fraction=0.5) == 1  # clamped to wide


def test_zoom_for_size_follows_the_measured_curve() -> None:
    """A lens whose focal length grows slowly, then steeply: the step for a focal length is
    read off its own curve, not the straight line."""
    lens = PtzLens(ZoomCurve((1, 5000, 8000, 9999), (743.0, 1564.0, 3520.0, 8996.0)))
    zoom = zoom_for_size(6000, object_mm=500, image_fraction=0.5, lens=lens)
    assert lens.intrinsics(zoom).fz_px == pytest.approx(0.5 * 576 * 6000 / 500, rel=1e-3)
    hd = PtzLens(lens.curve.scaled(1920 / 704), width_px=1920, height_px=1080)  # square pixels
    assert hd.intrinsics(zoom_for_size(6000, object_mm=500, image_fraction=0.5, lens=hd)
                         ).fz_px == pytest.approx(0.5 * 1080 * 6000 / 500, rel=1e-3)
    assert zoom != zoom_for_size(6000, object_mm=500, image_fraction=0.5)


def test_prediction_is_bounded() -> None:
    p, v = np.array([0.0, 0.0, 0.0]), np.array([290.0, 0.0, 0.0])
    np.testing.assert_allclose(predict(p, v, 0.2), [58.0, 0.0, 0.0])
    np.testing.assert_allclose(predict(p, v, 10.0), [145.0, 0.0, 0.0])  # at most 0.5 s


def test_the_aim_command_takes_a_negative_target_and_the_calib_services_pose_file(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--target -1200,300,0`` used to fail ("expected one argument") and ``--pose`` refused
    the pose file the calibration service writes."""
    from services.calib.store import PoseStore
    from services.ptz.aim_cli import main

    mount = Pose(3550.0, 1090.0, 2190.0, 180.0, 30.0, 165.0)
    stored = PoseStore(tmp_path).save(m.CameraPose(
        measured_s=1.0, camera="ptz1", **mount.fields(), focal_px=743.1, mean_error_px=0.5,
        passpoints=100), {"method": "auto"})
    solved = tmp_path / "solved.json"
    solved.write_text(json.dumps({"position_mm": [mount.x_mm, mount.y_mm, mount.z_mm],
                                  "orientation_deg": [mount.rx_deg, mount.ry_deg,
                                                      mount.rz_deg]}))
    target = np.array([-1200.0, 300.0, 0.0])
    for pose_file in (stored, solved):
        assert main(["--pose", str(pose_file), "--target", "-1200,300,0", "--json"]) == 0
        out = json.loads(capsys.readouterr().out)
        assert aim_error_deg(target, mount, out["pan_deg"], out["tilt_deg"]) < 1e-6
