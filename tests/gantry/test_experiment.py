"""``stb experiment gantry``: fields, a custom trajectory, plots, and clear errors; and the
OpenCV frame source on a video file."""

from __future__ import annotations

import json
import threading
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from services.gantry.cycle import AFTER_REPORT_S
from services.gantry.experiment import make_lab, run
from services.gantry.experiment_cli import main
from services.gantry.frames import OpenCvFrames


def test_a_custom_path_runs_every_algorithm_with_plots(tmp_path: Path, crater_file: Path,
                                                       capsys) -> None:  # noqa: ANN001
    t = np.arange(0, 12.01, 0.5)
    path = tmp_path / "path.csv"
    path.write_text("t,x,y\n" + "\n".join(f"{ti},{-600 + 80 * ti},{200 * np.sin(ti / 3)}"
                                            for ti in t) + "\n")
    code = main(["gantry", "--scenario", "locomotive", "--trajectory", str(path),
                 "--algorithm", "all", "--crater", str(crater_file), "--plot",
                 str(tmp_path / "plots"), "--json"])
    assert code == 0
    report = json.loads(capsys.readouterr().out)
    assert [r["algorithm"] for r in report["results"]] == [
        "basic", "pf-position", "pf-position-gauss", "pf-velocity", "default"]
    for r in report["results"]:
        assert {"std_x_mm", "std_y_mm", "rms_mm", "max_mm"} <= set(r)
        assert r["rms_mm"] < 150.0, r  # an 80 mm/s path is followed closely
        assert r["sim_s"] == pytest.approx(12.0, abs=0.3)
    for name in ("locomotive-errors.png", "locomotive-velocity.png"):
        assert (tmp_path / "plots" / name).read_bytes()[:4] == b"\x89PNG"


@pytest.mark.parametrize(("content", "message"), [
    ("t,x\n0,1\n1,2\n", "header must be t,x,y"),
    ("t,x,y\n0,1,2\n", "≥ 2 rows"),
    ("t,x,y\n0,1,2\n0,3,4\n", "increasing t"),
])
def test_a_bad_trajectory_file_is_named(tmp_path: Path, crater_file: Path, capsys,  # noqa: ANN001
                                        content: str, message: str) -> None:
    path = tmp_path / "bad.csv"
    path.write_text(content)
    assert main(["gantry", "--trajectory", str(path), "--algorithm", "basic",
                 "--crater", str(crater_file)]) == 2
    assert message in capsys.readouterr().err


def test_runs_are_reproducible_from_the_seed(crater_file: Path) -> None:
    results = [run(make_lab("walker", 3, crater_file), "pf-position", marker_height_mm=350.0,
                   seed=3, end_s=15.0).summary() for _ in range(2)]
    for r in results:
        r.pop("wall_s")
        r.pop("speedup")
    assert results[0] == results[1]


def test_a_missing_crater_is_the_same_whichever_seed_runs_first(tmp_path: Path) -> None:
    first, other = tmp_path / "a" / "crater.npz", tmp_path / "b" / "crater.npz"
    first.parent.mkdir()
    other.parent.mkdir()
    make_lab("walker", 3, first)
    make_lab("locomotive", 1, other)
    assert np.array_equal(np.load(first)["heights_mm"], np.load(other)["heights_mm"])


def test_the_gantry_ticks_a_fixed_time_after_the_crane_reports(crater_file: Path) -> None:
    """The run starts out of step (its first tick 0.2 s after the controller's cycle, where
    every algorithm makes the crane chase itself) and, once the crane moves, settles at
    ``AFTER_REPORT_S`` after each report (plus up to a 25 ms poll)."""
    r = run(make_lab("locomotive", 1, crater_file), "basic", marker_height_mm=80.0,
            end_s=20.0)
    assert r.report_age_s[0] == pytest.approx(0.195, abs=0.01)
    assert np.all(np.abs(np.array(r.report_age_s[20:]) - AFTER_REPORT_S) < 0.03)  # after 5 s


def test_opencv_frames_from_a_video_file(tmp_path: Path) -> None:
    video = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 25, (64, 48))
    for i in range(10):
        frame = np.full((48, 64, 3), 10, np.uint8)
        cv2.circle(frame, (10 + 4 * i, 20), 3, (255, 255, 255), -1)
        writer.write(frame)
    writer.release()
    stop = threading.Event()
    source = OpenCvFrames(str(video), stop)
    try:
        deadline = time.monotonic() + 5
        frame = None
        while frame is None and time.monotonic() < deadline:
            frame = source.take()
            time.sleep(0.01)
        assert frame is not None
        captured, image = frame
        assert image.shape == (48, 64) and image.dtype == np.uint8
        assert abs(captured - time.time()) < 5
    finally:
        stop.set()
