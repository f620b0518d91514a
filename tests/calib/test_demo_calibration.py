"""What ``make demo`` does on a fresh checkout: the sim's wand moves and the robot waits, the
calib service collects for both cameras by itself (as many passpoints as the demo's lab file
asks), the poses match the sim's mounts, the robot starts, the cameras follow it, and the
crane's observation camera (the page's bird's-eye view) is on the bus."""

from __future__ import annotations

import signal
import time
from pathlib import Path

import numpy as np
import pytest

from common import keys
from common import messages as m
from common.bus import Bus
from common.camera import Pose
from common.settings import load_settings
from services.calib.settings import CalibSettings
from services.sim.settings import SimSettings
from services.supervisor import UpSettings
from tests.calib.test_collect_e2e import _pose_of
from tests.calib.test_solve import errors
from tests.conftest import ROOT, client_settings, stb_process, wait_for
from tests.services.test_processes import _lab_for_up, _open_when_up, _stop

MOUNTS = {"ptz1": Pose(3550, 1090, 2190, 180, 30, 165),
          "ptz2": Pose(-3300, -1800, 2600, 164, -27, -33)}  # as write_lab configures the sim


DEMO = ROOT / "config" / "demo.toml"


def test_demo_config_calibrates_first_and_runs_the_observation_camera() -> None:
    assert load_settings(SimSettings, DEMO).calibrate_first == ["ptz1", "ptz2"]
    assert load_settings(CalibSettings, DEMO).collect_missing
    assert "observation" in load_settings(UpSettings, DEMO).services


@pytest.mark.system
def test_fresh_lab_calibrates_both_cameras_then_the_robot_starts(tmp_path: Path) -> None:
    lab, endpoint = _lab_for_up(tmp_path)  # every service: the observation camera's too
    count = load_settings(CalibSettings, DEMO).count
    env = {"STB_SIM__CALIBRATE_FIRST": '["ptz1", "ptz2"]', "STB_CALIB__COLLECT_MISSING": "true",
           "STB_CALIB__COUNT": str(count)}
    up = stb_process("up", "--lab", str(lab), "--no-view", env=env)
    session = None
    try:
        session = _open_when_up(endpoint)
        bus = Bus(session, client_settings(endpoint))
        poses: dict[str, m.CameraPose] = {}
        bus.subscribe(keys.CALIB_POSE, lambda p: poses.__setitem__(p.camera, p), latest=False)
        robot: list[m.RobotTruth] = []
        bus.subscribe(keys.TRUTH_ROBOT, robot.append, latest=False)
        states: dict[str, m.PtzState] = {}
        bus.subscribe(keys.PTZ_STATE, lambda s: states.__setitem__(s.camera, s), latest=False)
        bird: list[m.CameraFrame] = []
        bus.subscribe(keys.VIDEO, bird.append, latest=False, camera="observation")

        wait_for(lambda: robot, timeout=20)
        started = time.monotonic()
        wait_for(lambda: len(poses) == 2, timeout=150, period=0.5)
        print(f"both cameras calibrated {time.monotonic() - started:.0f} s after the sim was up")
        waiting = [r for r in robot if r.measured_s < min(p.measured_s for p in poses.values())]
        assert len(waiting) > 20
        first = np.array([waiting[0].x_mm, waiting[0].y_mm])
        assert all(np.hypot(r.x_mm - first[0], r.y_mm - first[1]) < 1.0 for r in waiting), \
            "the robot waits while the cameras are calibrated"
        for camera, pose in poses.items():
            position, angle = errors(_pose_of(pose), MOUNTS[camera])
            print(f"{camera}: {position:.1f} mm, {angle:.3f}° from the mount; "
                  f"{pose.mean_error_px:.2f} px")
            assert position < 10.0 and angle < 0.2
            assert 0.9 * count <= pose.passpoints <= count, "the demo's count (inliers)"
        wait_for(lambda: bird, timeout=10)
        assert bird[-1].encoding == "jpeg" and (bird[-1].width_px, bird[-1].height_px) == \
            (640, 480)
        wait_for(lambda: np.hypot(robot[-1].x_mm - first[0], robot[-1].y_mm - first[1]) > 100,
                 timeout=10)
        wait_for(lambda: all(states.get(c) is not None and states[c].status == "tracking"
                             for c in MOUNTS), timeout=10)
        bus.close()
    finally:
        if session is not None:
            session.close()
        assert _stop(up, signal.SIGINT, timeout=15) == 0


@pytest.mark.system
def test_a_collection_that_sees_nothing_fails_saying_why_and_the_robot_starts(
        tmp_path: Path) -> None:
    """ptz1 held looking at the sky: no passpoint comes; after ``stall_s`` the collection fails
    with the snapshots' story, and the sim starts the robot with ptz1 uncalibrated."""
    lab, endpoint = _lab_for_up(tmp_path)
    env = {"STB_SIM__CALIBRATE_FIRST": '["ptz1"]', "STB_CALIB__COLLECT_MISSING": "true",
           "STB_CALIB__CAMERAS": '["ptz1"]', "STB_CALIB__STALL_S": "4",
           "STB_CALIB__HOLD": '{"ptz1": {"pan_deg": 0, "tilt_deg": 85, "zoom": 1}}'}
    up = stb_process("up", "--lab", str(lab), "--no-view", env=env)
    session = None
    try:
        session = _open_when_up(endpoint)
        bus = Bus(session, client_settings(endpoint))
        progress: list[m.CollectProgress] = []
        bus.subscribe(keys.CALIB_PROGRESS, progress.append, latest=False)
        robot: list[m.RobotTruth] = []
        bus.subscribe(keys.TRUTH_ROBOT, robot.append, latest=False)
        states: dict[str, m.PtzState] = {}
        bus.subscribe(keys.PTZ_STATE, lambda s: states.__setitem__(s.camera, s), latest=False)
        wait_for(lambda: robot and progress, timeout=30)
        first = np.array([robot[0].x_mm, robot[0].y_mm])
        failed = wait_for(lambda: next((p for p in progress if p.state == "failed"), None),
                          timeout=30)
        print(failed.message)
        assert failed.camera == "ptz1" and failed.passpoints == 0
        assert "no passpoint for 4 s" in failed.message and "no marker" in failed.message
        assert "not in the camera's view" in failed.message
        wait_for(lambda: np.hypot(robot[-1].x_mm - first[0], robot[-1].y_mm - first[1]) > 100,
                 timeout=15)  # the demo carries on
        wait_for(lambda: states.get("ptz1") is not None
                 and states["ptz1"].status == "waiting_for_pose", timeout=10)
        bus.close()
    finally:
        if session is not None:
            session.close()
        assert _stop(up, signal.SIGINT, timeout=15) == 0
