"""``stb calib collect --zooms`` against the sim, as processes under ``stb up``: the sim's ptz1
has a lens drawn at random (a bent zoom curve and barrel distortion, set in its lab file, never
read by a service); the calib service measures it from the camera's own pictures."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from common import keys
from common import messages as m
from common.bus import Bus
from common.camera import Pose
from common.ptz_lens import PtzLens, measured_lens
from tests.calib.test_solve import errors
from tests.calib.test_zoom_fit import STEPS, distortion_error_px, drawn_lens
from tests.conftest import ROOT, client_settings, stb_process, wait_for
from tests.services.test_processes import AliveWatcher, _lab_for_up, _open_when_up, _stop

PTZ1_MOUNT = Pose(3550, 1090, 2190, 180, 30, 165)  # as write_lab configures the sim
ZOOMS = [1, 3000, 5500, 7000, 8000, 9000, 9999]


def _with_lens(lab: Path, lens: PtzLens) -> None:
    """ptz1's lens in the sim's lab file, as a lab engineer would write it down."""
    table = ", ".join(f"[{z:.0f}, {f!r}]" for z, f in lens.curve.points())
    wide, long = lens.distortions
    text = lab.read_text().replace("rz_deg = 165\n", "rz_deg = 165\n"
                                   f"zoom_focal_mm = [{table}]\n"
                                   f"distortion = {list(wide)}\n"
                                   f"distortion_long = {list(long)}\n", 1)
    lab.write_text(text.replace(
        "[up]\n", '[up]\nservices = ["router", "sim", "tracker", "calib", "ptz:ptz1"]\n', 1))


@pytest.mark.system
@pytest.mark.parametrize("seed", [11])
def test_collect_at_several_zooms_measures_the_sim_cameras_lens(tmp_path: Path,
                                                                 seed: int) -> None:
    truth = drawn_lens(np.random.default_rng(seed))
    lab, endpoint = _lab_for_up(tmp_path)
    _with_lens(lab, truth)
    env = {"STB_SIM__SCENARIO": "calibration"}
    up = stb_process("up", "--lab", str(lab), "--no-view", env=env)
    session = None
    try:
        session = _open_when_up(endpoint)
        bus = Bus(session, client_settings(endpoint))
        alive = AliveWatcher(session)
        for key in ("calib/main", "ptz/ptz1", "tracker/main", "sim/main"):
            wait_for(lambda k=key: alive.alive(f"stb/alive/{k}"), timeout=30)
        started = time.monotonic()
        collect = subprocess.run(
            [sys.executable, "-m", "services.cli", "calib", "collect", "--camera", "ptz1",
             "--count", "90", "--timeout", "600", "--zooms", ",".join(map(str, ZOOMS)),
             "--lab", str(lab)],
            cwd=ROOT, capture_output=True, text=True, timeout=900,
            env={**os.environ, **env})
        print(collect.stdout[-3000:], collect.stderr[-3000:])
        print(f"collected and solved in {time.monotonic() - started:.0f} s")
        assert collect.returncode == 0, collect.stderr
        (pose,) = bus.query_latest(keys.CALIB_POSE, timeout_s=2.0, camera="ptz1")
        bus.close()
    finally:
        if session is not None:
            session.close()
        assert _stop(up, signal.SIGINT, timeout=15) == 0
    assert isinstance(pose, m.CameraPose) and [p.zoom for p in pose.lens] == ZOOMS
    lens = measured_lens([(p.zoom, p.focal_mm, p.distortion) for p in pose.lens])
    focal_error = max(abs(lens.focal_mm(z) / truth.focal_mm(z) - 1) for z in STEPS)
    distortion_px = distortion_error_px(lens.intrinsics(1), truth.intrinsics(1))
    position, angle = errors(Pose.of(pose), PTZ1_MOUNT)
    print(f"seed {seed}: focal within {100 * focal_error:.2f} % at every step, distortion "
          f"within {distortion_px:.2f} px at zoom 1, pose {position:.1f} mm / {angle:.3f}°, "
          f"{pose.mean_error_px:.2f} px over {pose.passpoints} passpoints")
    assert focal_error < 0.02
    assert distortion_px <= 1.0
    assert position < 10.0 and angle < 0.2  # as the single-zoom collection (test_collect_e2e)
