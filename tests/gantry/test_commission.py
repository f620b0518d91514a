"""A crane's first day against a simulated lab whose every geometric truth differs from the
code's defaults (drawn at random, seeded: tests/geometry_truths.py): before commissioning the
gantry refuses to arm and says why; after ``stb sim scan`` → ``stb crater import`` →
``stb gantry commission`` the truths come back, the gantry arms, and the locomotive is followed
as well as in the ideal lab (the same run of the live controller on a simulated clock)."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import numpy as np
import pytest
import tomli_w

from common import messages as m
from common.heightmap import HeightMap
from common.tracking_camera import TrackingCameraModel
from services.gantry.commissioning.geometry_fit import distortion_difference_px
from services.sim.lab import load_or_make_crater
from services.sim.settings import SimSettings
from tests.conftest import ROOT, client_settings, open_when_up, poll, stb_process
from tests.gantry.rig import Operator
from tests.geometry_truths import askew_lab_file, draw_truths
from tests.ports import free_port
from tests.services.test_processes import _stop

SEED = 7
FOLLOW_FACTOR, FOLLOW_SLACK_MM = 1.10, 5.0  # the goal: within 10 % (+5 mm) of ideal
STARTING = ("no fresh estimate", "the crane controller does not answer",
            "no recent comparison with the motion capture")
"""refusals of a lab still starting (the gantry's first frame, its first Modbus reading, its
first cross-check of the crane against the motion capture; the load tally saw the second, a
run after it the third): the operator asks again"""


def _stb(*args: str, timeout: float = 600.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "services.cli", *args], capture_output=True,
                          text=True, timeout=timeout, cwd=ROOT)


def _arm_answer(endpoint: str, until: float) -> str:
    session = open_when_up(client_settings(endpoint).zenoh)
    from common.bus import Bus

    bus = Bus(session, client_settings(endpoint))
    try:
        operator = Operator(bus)
        reply: m.GantryCommandReply | None = None

        def answered() -> bool:  # accepted, or refused for more than a lab still starting
            nonlocal reply
            if not operator.states:  # the gantry is not up yet
                return False
            ident = operator._publish("arm")
            reply = poll(lambda: operator._reply(ident), timeout=3)
            return reply is not None and (reply.accepted or not any(
                starting in reply.detail for starting in STARTING))

        poll(answered, timeout=until - time.monotonic(), period=1.0)  # asked again each second
        if reply is None:
            return "no answer"
        return ("accepted: " if reply.accepted else "refused: ") + reply.detail
    finally:
        bus.close()
        session.close()


@pytest.mark.system
@pytest.mark.timeout(900)
def test_the_first_day_measures_the_lab_that_is_there(tmp_path: Path) -> None:
    crane, camera = draw_truths(SEED)
    truth_map = tmp_path / "truth.npz"
    truth = load_or_make_crater(SimSettings(crater_file=truth_map, seed=SEED))
    # the laser scan, and the gantry's height map from it
    scan, imported = tmp_path / "scan.ply", tmp_path / "imported.npz"
    made = _stb("sim", "scan", "--out", str(scan), "--set", f"crater_file={truth_map}")
    assert made.returncode == 0, made.stderr
    done = _stb("crater", "import", str(scan), "--out", str(imported))
    assert done.returncode == 0, done.stderr
    heights = HeightMap.load(imported)
    rows, cols = heights.heights_mm.shape
    xs = heights.origin_x_mm + np.arange(cols) * heights.resolution_mm
    ys = heights.origin_y_mm + np.arange(rows) * heights.resolution_mm
    error = np.abs(heights.heights_mm - truth.height_at(*np.meshgrid(xs, ys)))
    assert np.percentile(error, 99) <= 5.0, "the imported crater (holes filled included)"

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    lab = askew_lab_file(tmp_path, endpoint, truth_map, imported, crane, camera)
    up = stb_process("up", "--lab", str(lab), "--no-view")
    try:
        said = _arm_answer(endpoint, time.monotonic() + 60)
        assert said.startswith("refused: ") and "crane's position" in said, said
        assert "disagrees with the motion capture" in said and "stb gantry commission" in said
        started = time.monotonic()
        measured = _stb("gantry", "commission", "--lab", str(lab), "--yes", "--json",
                        "--toml", str(tmp_path / "commissioned.toml"))
        print(measured.stderr[-3000:])
        assert measured.returncode == 0, measured.stderr
        print(f"commissioning took {time.monotonic() - started:.0f} s")
    finally:
        _stop(up, signal.SIGINT, timeout=30)
    result = json.loads(measured.stdout)
    frame, found = result["frame"], result["camera"]
    assert (frame["flip_x"], frame["flip_y"]) == (False, True)
    assert np.hypot(*np.subtract(frame["origin_mm"], crane["origin_mm"])) <= 5.0
    assert frame["yaw_deg"] == pytest.approx(crane["yaw_deg"], abs=0.1)
    assert found["focal_mm"] == pytest.approx(camera["focal_mm"], rel=0.01)  # drawn, 6–12 mm
    assert found["yaw_deg"] == pytest.approx(camera["yaw_deg"], abs=0.1)
    assert np.hypot(*np.subtract(found["offset_mm"], camera["offset_mm"])) <= 5.0
    fitted = TrackingCameraModel(**{k: found[k] for k in TrackingCameraModel.model_fields})
    assert distortion_difference_px(fitted, TrackingCameraModel(**camera)) <= 1.0
    # how long the crane moves is a performance target (≤ 3 min): benchmarks.commissioning
    # measures it on an idle machine; here, beside other load, it is only reported
    print(f"the crane's motion: {result['motion_s']:.0f} s")

    # the commissioned lab: the fragment merged into the lab file; the gantry arms now
    fragment = tomllib.loads((tmp_path / "commissioned.toml").read_text())
    commissioned = askew_lab_file(tmp_path / "commissioned", f"tcp/127.0.0.1:{free_port()}",
                             truth_map, imported, crane, camera,
                             extra={"gantry": fragment["gantry"]})
    doc = tomllib.loads(commissioned.read_text())
    endpoint = doc["router"]["listen"][0]
    up = stb_process("up", "--lab", str(commissioned), "--no-view")
    try:
        said = _arm_answer(endpoint, time.monotonic() + 60)
        assert said.startswith("accepted: "), said
    finally:
        _stop(up, signal.SIGINT, timeout=30)

    # the locomotive, followed through the commissioned geometry as in the ideal lab
    ideal = _follow(tmp_path / "ideal.toml", truth_map, None, {}, {}, {})
    askew = _follow(tmp_path / "askew.toml", truth_map, imported, crane, camera,
                    {"crane": doc["gantry"]["crane"],
                     "tracking_camera": doc["gantry"]["tracking_camera"]})
    print(f"locomotive crane rms: ideal lab {ideal:.1f} mm, commissioned lab {askew:.1f} mm")
    assert askew <= max(FOLLOW_FACTOR * ideal, ideal + FOLLOW_SLACK_MM)


def _follow(lab: Path, truth_map: Path, gantry_map: Path | None, crane: dict, camera: dict,
            gantry: dict) -> float:
    """The crane's rms distance to the locomotive: the live controller on a simulated clock
    (stb experiment gantry) in a lab with these truths and this gantry's view."""
    lab.write_text(tomli_w.dumps({"sim": {"crane": crane, "tracking_camera": camera},
                                  "gantry": gantry}))
    args = ["experiment", "gantry", "--scenario", "locomotive", "--algorithm", "default",
            "--lab", str(lab), "--crater", str(truth_map), "--json"]
    if gantry_map is not None:
        args += ["--gantry-map", str(gantry_map)]
    done = _stb(*args)
    assert done.returncode == 0, done.stderr
    return float(json.loads(done.stdout)["results"][0]["rms_mm"])
