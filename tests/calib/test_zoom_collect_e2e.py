"""``stb calib collect --zooms`` against the sim, as processes under ``stb up``: the sim's ptz1
has a lens drawn at random (a bent zoom curve and barrel distortion, set in its lab file, never
read by a service); the calib service measures it from the camera's own pictures. Then the
locomotive starts and ptz1 follows it at the longest zoom for half a minute, judged by the sim's
truth: where the robot really is in the camera's picture."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from common import keys
from common import messages as m
from common.bus import Bus
from common.camera import Intrinsics, Pose, head_pose, project
from common.ptz_lens import PtzLens, axis_215_px, lens_of
from services.sim.settings import PtzCameraSettings
from tests.calib.test_collect_e2e import calibration_lab
from tests.calib.test_solve import errors
from tests.calib.test_zoom_fit import (
    EDGE_BAND,
    STEPS,
    ZOOMS,
    distortion_error_px,
    drawn_camera,
    sim_camera,
)
from tests.conftest import ROOT, ahead_of_other_work, wait_for
from tests.services.test_processes import _lab_for_up

PTZ1_MOUNT = Pose(3550, 1090, 2190, 180, 30, 165)  # as write_lab configures the sim
TRUTH_HZ = 20  # the sim's truth_rate_hz
FOLLOW_S = 30.0  # 600 true views


def lens_fields(lens: PtzLens) -> dict[str, Any]:
    """An AXIS 215 lens (``drawn_lens``) as ``[[sim.cameras]]`` fields, as a lab engineer
    would write it down (focal lengths in mm on the sim's chip, the AXIS 215's)."""
    in_mm = lens.curve.scaled(1 / axis_215_px(1.0))
    wide, long = lens.distortions
    return {"zoom_focal_mm": [[z, f] for z, f in in_mm.points()], "distortion": list(wide),
            "distortion_long": list(long)}


def with_camera(lab: Path, fields: dict[str, Any]) -> None:
    """ptz1's lens and head in the sim's lab file (never read by a service but the sim)."""
    lines = "".join(f"{key} = {json.dumps(value)}\n" for key, value in fields.items())
    text = lab.read_text().replace("rz_deg = 165\n", "rz_deg = 165\n" + lines, 1)
    text = text.replace("[sim]\n", '[sim]\nscenario = "locomotive"\ncalibrate_first = ["ptz1"]\n',
                        1).replace("[ptz.cameras.ptz1]\n", f"[ptz]\nzoom = {ZOOMS[-1]}\n"
                                   "[ptz.cameras.ptz1]\n", 1)
    lab.write_text(text.replace(
        "[up]\n", '[up]\nservices = ["router", "sim", "tracker", "calib", "ptz:ptz1"]\n', 1))


def true_pixels(truths: list[tuple[m.PtzTruth, m.RobotTruth]], camera: PtzCameraSettings
                ) -> tuple[np.ndarray, list[Intrinsics]]:
    """Where the robot's true marker is in each of the camera's true views (pixels: through
    its true head and lens), and the true lens at each view's zoom."""
    head, lens = camera.head(), camera.lens()
    uv, lenses = [], []
    for view, robot in truths:
        intr = lens.intrinsics(view.zoom)
        uv.append(project(np.array([[robot.x_mm, robot.y_mm, robot.z_mm]]),
                          head.pose_at(view.pan_deg, view.tilt_deg), intr)[0])
        lenses.append(intr)
    return np.array(uv).reshape(-1, 2), lenses


def central_share(truths: list[tuple[m.PtzTruth, m.RobotTruth]], camera: PtzCameraSettings
                  ) -> float:
    """The share of the camera's true views in which the robot's true marker is within the
    central 40 % of the picture's width."""
    uv, lenses = true_pixels(truths, camera)
    inside = [0.3 * intr.width_px <= u <= 0.7 * intr.width_px
              for (u, _), intr in zip(uv, lenses, strict=True)]
    return sum(inside) / len(truths)


def collect(lab: Path, zooms: list[int], count: int) -> subprocess.CompletedProcess:
    """``stb calib collect`` for ptz1 (at one zoom when ``zooms`` is empty)."""
    at = ["--zooms", ",".join(map(str, zooms))] if zooms else []
    started = time.monotonic()
    done = subprocess.run(
        [sys.executable, "-m", "services.cli", "calib", "collect", "--camera", "ptz1",
         "--count", str(count), "--timeout", "900", *at, "--lab", str(lab)],
        cwd=ROOT, capture_output=True, text=True, timeout=1000, env=dict(os.environ),
        preexec_fn=ahead_of_other_work())
    print(done.stdout[-2000:], done.stderr[-3000:])
    print(f"collected and solved in {time.monotonic() - started:.0f} s")
    return done


def follow(bus: Bus, seconds: float) -> list[tuple[m.PtzTruth, m.RobotTruth]]:
    """ptz1's true pan, tilt and zoom beside the robot's true marker, 20 a second, for
    ``seconds`` of following once the locomotive has moved for 5 s (the camera turned onto it
    and zoomed in)."""
    seen: dict[float, m.PtzTruth | m.RobotTruth] = {}  # the sim sends both with one stamp
    truths: list[tuple[m.PtzTruth, m.RobotTruth]] = []

    def paired(msg: m.PtzTruth | m.RobotTruth) -> None:
        other = seen.pop(msg.measured_s, None)
        if other is None:
            seen[msg.measured_s] = msg
            return
        camera, robot = (msg, other) if isinstance(msg, m.PtzTruth) else (other, msg)
        assert isinstance(camera, m.PtzTruth) and isinstance(robot, m.RobotTruth)
        if np.hypot(robot.vx_mm_s, robot.vy_mm_s) > 0:  # the locomotive has started
            truths.append((camera, robot))

    bus.subscribe(keys.TRUTH_PTZ, paired, latest=False, camera="ptz1")
    bus.subscribe(keys.TRUTH_ROBOT, paired, latest=False, robot="*")
    wait_for(lambda: len(truths) > 0, timeout=30, why=lambda: "the locomotive never moved")
    settled = len(truths) + 5 * TRUTH_HZ
    wanted = int(seconds * TRUTH_HZ)
    wait_for(lambda: len(truths) >= settled + wanted, timeout=2 * seconds + 30,
             why=lambda: f"{len(truths)} true views")
    return truths[settled:settled + wanted]


@pytest.mark.system
@pytest.mark.timeout(1200)  # 2.5–5 minutes of collection (corners at zoom 1), half a minute
# following
@pytest.mark.parametrize("seed", [11])  # an AXIS 215 lens drawn at random:
# benchmarks.long_zoom --seed N (CI time: each camera is minutes of real-time collection)
def test_collect_at_several_zooms_measures_a_16_9_cameras_lens(tmp_path: Path,
                                                                seed: int) -> None:
    """A current camera: 1920 × 1080, its own chip and zoom range, the principal point off
    the centre and a head whose axes do not meet at the lens, all drawn; the services know
    none of it but what the camera's VAPIX says (its picture sizes)."""
    fields = drawn_camera(np.random.default_rng(seed))
    camera = sim_camera(fields, PTZ1_MOUNT)
    truth = camera.lens()
    lab, endpoint = _lab_for_up(tmp_path)
    with_camera(lab, fields)
    # the lens as the lab's own machine measures it, not beside another test's lab: the
    # snapshots' timing under the other worker's load spread the passpoints (mean error
    # 1.25 px against 0.41 idle in a CI run, the distortion then 1.05 px against its 1 px)
    with calibration_lab(lab, endpoint, {}, ahead=True) as bus:
        collected = collect(lab, ZOOMS, count=90)
        assert collected.returncode == 0, collected.stderr
        (pose,) = bus.query_latest(keys.CALIB_POSE, timeout_s=2.0, camera="ptz1")
        # the pose is on the bus: the sim starts the locomotive, ptz1 follows at the long end
        following = follow(bus, FOLLOW_S)
    assert isinstance(pose, m.CameraPose) and [p.zoom for p in pose.lens] == ZOOMS
    assert (pose.width_px, pose.height_px) == (1920, 1080)
    assert (tmp_path / "calib" / "ptz1" / "lens.png").stat().st_size > 10_000
    lens = lens_of(pose)
    focal_error = max(abs(lens.focal_px(z) / truth.focal_px(z) - 1) for z in STEPS)
    distortion_px = distortion_error_px(lens.intrinsics(1), truth.intrinsics(1))
    covered_px = distortion_error_px(lens.intrinsics(1), truth.intrinsics(1), inset=EDGE_BAND)
    principal = np.array([pose.principal_u_px, pose.principal_v_px], dtype=float)
    principal_px = float(np.linalg.norm(principal - [truth.intrinsics(1).cy_px,
                                                     truth.intrinsics(1).cz_px]))
    hold = json.loads((tmp_path / "calib" / "ptz1" / "pose.json").read_text())["report"]
    held = (hold["pan_deg"], hold["tilt_deg"])  # the camera's pose where it was held
    position, angle = errors(head_pose(Pose.of(pose), *held), camera.head().pose_at(*held))
    print(f"seed {seed}: focal within {100 * focal_error:.2f} % at every step, distortion "
          f"within {covered_px:.2f} px at zoom 1 ({distortion_px:.2f} px at the very edge), "
          f"principal point {principal_px:.2f} px off, pose {position:.1f} mm / {angle:.3f}°, "
          f"{pose.mean_error_px:.2f} px over {pose.passpoints} passpoints")
    # the AXIS 215's bounds in its 704-wide picture, as the same angles in this one's pixels:
    # the passpoints' noise is the motion capture's and the snapshots' timing, in angle
    scale = pose.width_px / 704
    print(f"in the AXIS 215's pixels: distortion {covered_px / scale:.2f} px "
          f"({distortion_px / scale:.2f} px at the very edge)")
    assert focal_error < 0.02
    assert covered_px <= 1.0 * scale and distortion_px <= 2.0 * scale
    assert principal_px <= 2.0
    assert position < 10.0 and angle < 0.2  # as the single-zoom collection (test_collect_e2e)
    share = central_share(following, camera)
    print(f"following at zoom {ZOOMS[-1]}: the robot within the central 40 % of the picture in "
          f"{100 * share:.1f} % of {len(following)} true views over {FOLLOW_S:g} s")
    assert share >= 0.95
