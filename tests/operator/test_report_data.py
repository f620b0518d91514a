"""The report's figures from known series (pure), and its command's errors."""

from __future__ import annotations

import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from common import codec, keys
from common import messages as m
from common.camera import Pose
from common.mcap_file import RecordWriter
from services.args import EXIT_DISK
from services.calib.synthetic import PAPER_POSE, moving_marker
from services.report.data import Recording, calibration_residuals, crane_error, summary
from tests.conftest import ROOT, stb_process


def _pose_msg(pose: Pose, camera: str = "ptz1") -> m.CameraPose:
    return m.CameraPose(measured_s=0.0, camera=camera, x_mm=pose.x_mm, y_mm=pose.y_mm,
                        z_mm=pose.z_mm, rx_deg=pose.rx_deg, ry_deg=pose.ry_deg,
                        rz_deg=pose.rz_deg, focal_px=743.1, mean_error_px=1.0, passpoints=80)


def _calibration_run(pose_msg: m.CameraPose, rng: np.random.Generator) -> Recording:
    points, track = moving_marker(PAPER_POSE, rng, count=60, offset_s=0.0, noise_px=1.0)
    assert points.times_s is not None
    rec = Recording(path=None)  # type: ignore[arg-type]
    rec.frames = [m.MarkerFrame(measured_s=float(t), frame=i, markers=[m.Marker(
        label="wand", x_mm=float(x), y_mm=float(y), z_mm=float(z))])
        for i, (t, (x, y, z)) in enumerate(zip(track.times_s, track.xyz_mm, strict=True))]
    rec.detections["ptz1"] = [m.MarkerDetections(
        measured_s=float(t), camera="ptz1", status="ok", threshold=230, width_px=704,
        height_px=576, markers=[m.DetectedMarker(u_px=float(u), v_px=float(v),
                                                 radius_long_px=3, radius_short_px=3,
                                                 angle_deg=0, roundness=1, area_px=28)])
        for t, (u, v) in zip(points.times_s, points.pixels, strict=True)]
    rec.ptz_state["ptz1"].add(float(track.times_s[0]), 0.0, 0.0, 1)
    rec.poses["ptz1"] = pose_msg
    return rec


def test_calibration_residuals_come_from_the_recorded_passpoints(
        rng: np.random.Generator) -> None:
    right = calibration_residuals(_calibration_run(_pose_msg(PAPER_POSE), rng))["ptz1"]
    assert len(right) >= 50, "the collector finds the passpoints again"
    assert np.median(right) < 2.5, "1 px noise → residuals of about 1.25 px"
    off = Pose(PAPER_POSE.x_mm + 200, PAPER_POSE.y_mm, PAPER_POSE.z_mm, PAPER_POSE.rx_deg,
               PAPER_POSE.ry_deg, PAPER_POSE.rz_deg)
    wrong = calibration_residuals(_calibration_run(_pose_msg(off), rng))["ptz1"]
    assert np.median(wrong) > 5 * np.median(right), "a wrong pose shows in the residuals"


def test_crane_error_compares_the_enabled_crane_with_the_robot_at_the_same_time() -> None:
    rec = Recording(path=None)  # type: ignore[arg-type]
    for i in range(101):  # robot along x at 100 mm/s, 100 Hz
        t = 10.0 + i * 0.01
        rec.robot.add(t, 100.0 * (t - 10.0), 0.0, 0.0, 100.0, 0.0)
    rec.crane.add(10.2, 0.0, 5.0, 1.0)   # 20 mm behind, 5 mm aside
    rec.crane.add(10.5, 40.0, 0.0, 1.0)  # 10 mm behind
    rec.crane.add(10.6, 0.0, 0.0, 0.0)   # disabled: not counted
    rec.crane.add(30.0, 0.0, 0.0, 1.0)   # no robot sample near: not counted
    times, error = crane_error(rec)
    assert times.tolist() == [10.2, 10.5]
    assert error == pytest.approx(np.array([[-20.0, 5.0], [-10.0, 0.0]]))
    rec.first_s, rec.last_s = 10.0, 11.0
    figures = summary(rec)
    assert figures["crane_error_max_mm"] == pytest.approx(np.hypot(20, 5), abs=0.1)
    assert figures["crane_error_mean_mm"] == pytest.approx((np.hypot(20, 5) + 10) / 2, abs=0.1)


def test_an_empty_recording_gives_figures_of_none() -> None:
    figures = summary(Recording(path=None))  # type: ignore[arg-type]
    assert figures["crane_error_mean_mm"] is None and figures["samples"] == 0


def test_bad_files_and_key_expressions_are_clear_errors(tmp_path: Path) -> None:
    bad = tmp_path / "bad.mcap"
    bad.write_text("hello")
    proc = stb_process("report", str(bad), "--out", str(tmp_path / "out"))
    assert proc.wait(timeout=60) == 2
    assert "not a readable MCAP recording" in proc.stderr.read()
    proc = stb_process("replay", str(tmp_path / "missing.mcap"))
    assert proc.wait(timeout=60) == 2
    assert "missing.mcap" in proc.stderr.read()
    proc = stb_process("record", str(tmp_path / "x.mcap"), "stb//tracker")
    assert proc.wait(timeout=60) == 2
    assert "bad key expression 'stb//tracker'" in proc.stderr.read()
    assert not (tmp_path / "x.mcap").exists(), "nothing written before the arguments are good"


def test_the_tracks_are_shown_zoomed_to_where_the_run_went(tmp_path: Path) -> None:
    from services.report.plots import track_plot, track_view

    rec = Recording(path=None)  # type: ignore[arg-type]
    assert track_view(rec) is None and track_plot(rec, None, tmp_path / "t.png") is None
    for i in range(50):  # a 2 m × 1 m oval's worth of the crater, far from its 8 m extent
        t = float(i)
        rec.robot.add(t, 1000.0 + 20.0 * i, -500.0 + 10.0 * i, 80.0, 0.0, 0.0)
        rec.crane.add(t, 990.0 + 20.0 * i, -490.0 + 10.0 * i, 1.0)
    rec.crane.add(50.0, float("nan"), 0.0, 1.0)  # a bad sample does not widen the view
    x0, x1, y0, y1 = track_view(rec, margin_mm=400.0)  # type: ignore[misc]
    assert (x0, x1, y0, y1) == pytest.approx((590.0, 2380.0, -900.0, 400.0))
    rec.poses["ptz1"] = _pose_msg(PAPER_POSE)
    written = track_plot(rec, None, tmp_path / "tracks.png")
    assert written is not None and written.stat().st_size > 10_000


def _small_recording(path: Path) -> None:
    with open(path, "wb") as f:
        writer = RecordWriter(f)
        for i in range(50):
            t = 1.7e9 + i * 0.1
            robot = m.RobotPosition(measured_s=t, label="robot", x_mm=float(i), y_mm=0.0,
                                    z_mm=0.0, vx_mm_s=0.0, vy_mm_s=0.0, vz_mm_s=0.0)
            writer.write(keys.TRACKER_ROBOT.key(keys.DEFAULT_PREFIX),
                         codec.encode(robot, sent_s=t), encoding=codec.CONTENT_TYPE,
                         model="RobotPosition", received_s=t, measured_s=t)
        writer.finish()


def test_a_report_that_cannot_be_written_is_a_clear_error(tmp_path: Path) -> None:
    """``--out`` a file, not a folder: exit 2 naming it (it ended in a traceback)."""
    _small_recording(recording := tmp_path / "run.mcap")
    proc = stb_process("report", str(recording), "--out", str(recording))
    assert proc.wait(timeout=120) == 2
    error = proc.stderr.read()
    assert f"cannot write the report to {recording}" in error and "Traceback" not in error


@pytest.mark.skipif(shutil.which("unshare") is None, reason="needs unshare(1)")
def test_a_report_onto_a_full_disk_exits_5_without_a_traceback(tmp_path: Path) -> None:
    """``--out`` on a real filesystem (a 1 MB tmpfs of its own) that is full."""
    _small_recording(recording := tmp_path / "run.mcap")
    (disk := tmp_path / "disk").mkdir()
    report = [sys.executable, "-m", "services.cli", "report", str(recording), "--out",
              str(disk / "report")]
    script = (f"mount -t tmpfs -o size=1m tmpfs {shlex.quote(str(disk))} || exit 99; "
              f"dd if=/dev/zero of={shlex.quote(str(disk / 'filler'))} bs=64k 2>/dev/null; "
              f"{shlex.join(report)}")
    done = subprocess.run(["unshare", "-m", "sh", "-c", script], cwd=ROOT, capture_output=True,
                          text=True, timeout=120)
    if done.returncode == 99:
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.strip()}")
    assert done.returncode == EXIT_DISK, done.stderr
    assert "No space left on device" in done.stderr and "free space" in done.stderr
    assert "Traceback" not in done.stderr
