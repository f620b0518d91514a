"""Collect → solve → publish against the sim, as processes under ``stb up``: the calib
service finds the sim camera's mount pose from the wand, keeps it across a restart, and
``stb calib solve`` gets the same pose back from the stored files."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from functools import partial
from pathlib import Path

import numpy as np
import pytest

from common import keys
from common import messages as m
from common.bus import Bus
from common.camera import Pose
from tests.calib.test_solve import errors
from tests.conftest import ROOT, ahead_of_other_work, client_settings, stb_process, wait_for
from tests.services.test_processes import AliveWatcher, _lab_for_up, _open_when_up, _stop

PTZ1_MOUNT = Pose(3550, 1090, 2190, 180, 30, 165)  # as write_lab configures the sim


def _pose_of(msg: m.CameraPose) -> Pose:
    return Pose(msg.x_mm, msg.y_mm, msg.z_mm, msg.rx_deg, msg.ry_deg, msg.rz_deg)


@contextmanager
def calibration_lab(lab: Path, endpoint: str, env: dict[str, str],
                    ahead: bool = False) -> Iterator[Bus]:
    """``stb up`` with the lab file, a bus client once the calibration's services are alive;
    on leaving, ``stb up`` is stopped and must exit cleanly. ``ahead``: the lab's processes
    scheduled ahead of the other worker's tests (``ahead_of_other_work``)."""
    up = stb_process("up", "--lab", str(lab), "--no-view", env=env,
                     preexec_fn=ahead_of_other_work() if ahead else None)
    session = None
    try:
        session = _open_when_up(endpoint)
        bus = Bus(session, client_settings(endpoint))
        alive = AliveWatcher(session)
        for key in ("calib/main", "ptz/ptz1", "tracker/main", "sim/main"):
            wait_for(partial(alive.alive, f"stb/alive/{key}"), timeout=30)
        yield bus
        bus.close()
    finally:
        if session is not None:
            session.close()
        assert _stop(up, signal.SIGINT, timeout=15) == 0


@pytest.mark.system
def test_collect_solve_publish_recovers_the_sim_camera(tmp_path: Path) -> None:
    lab, endpoint = _lab_for_up(tmp_path)
    # only what a collection needs (the line belongs to [up]: appended, it fell into [web]
    # and the whole lab ran); collect away from pan = tilt = 0: the mount must still come out
    lab.write_text(lab.read_text().replace(
        "[up]\n", '[up]\nservices = ["router", "sim", "tracker", "calib", "ptz:ptz1"]\n', 1)
        + "[calib.hold.ptz1]\npan_deg = 6.0\ntilt_deg = -4.0\n")
    env = {"STB_SIM__SCENARIO": "calibration"}
    with calibration_lab(lab, endpoint, env) as bus:
        states: list[m.PtzState] = []
        bus.subscribe(keys.PTZ_STATE, states.append, latest=False, camera="ptz1")
        healths: list[m.ServiceHealth] = []
        bus.subscribe(keys.HEALTH, healths.append, latest=False, service="calib")
        assert bus.query_latest(keys.CALIB_POSE, timeout_s=1.0, camera="ptz1") == []

        collect = subprocess.run(
            [sys.executable, "-m", "services.cli", "calib", "collect", "--camera", "ptz1",
             "--count", "100", "--timeout", "120", "--lab", str(lab)],
            cwd=ROOT, capture_output=True, text=True, timeout=150,
            env={**os.environ, **env})
        print(collect.stdout, collect.stderr)
        assert collect.returncode == 0, collect.stderr
        assert "ptz1: done" in collect.stdout

        (published,) = bus.query_latest(keys.CALIB_POSE, timeout_s=2.0, camera="ptz1")
        position, angle = errors(_pose_of(published), PTZ1_MOUNT)
        print(f"collected pose: {position:.1f} mm, {angle:.3f}° from the sim's mount; "
              f"{published.mean_error_px:.2f} px over {published.passpoints} passpoints")
        assert position < 10.0 and angle < 0.2
        assert published.passpoints >= 90
        assert any(s.status == "calibrating" for s in states)
        wait_for(lambda: states[-1].status in ("idle", "tracking"), timeout=5)

        folder = tmp_path / "calib" / "ptz1"
        assert len((folder / "passpoints.csv").read_text().splitlines()) == 101
        assert len(list((folder / "images").glob("*.jpg"))) >= 90

        pid = healths[-1].pid
        os.kill(pid, signal.SIGKILL)
        wait_for(lambda: any(h.pid != pid for h in healths), timeout=10)
        (again,) = bus.query_latest(keys.CALIB_POSE, timeout_s=2.0, camera="ptz1")
        assert again.measured_s == published.measured_s, "the restarted service kept the pose"

    solved = subprocess.run(
        [sys.executable, "-m", "services.cli", "calib", "solve", str(folder / "passpoints.csv"),
         "--mocap-track", str(folder / "track.csv"), "--json"],
        cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert solved.returncode == 0, solved.stderr
    report = json.loads(solved.stdout)
    stored = json.loads((folder / "pose.json").read_text())["report"]
    assert np.allclose(report["position_mm"], stored["position_mm"], atol=0.01)
    assert stored["pan_deg"] == 6.0 and stored["tilt_deg"] == -4.0
