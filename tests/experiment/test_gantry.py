"""``stb experiment gantry``: fields, a custom or recorded path, plots, the lab's settings, clear
errors; and the OpenCV frame source on a video file."""

from __future__ import annotations

import json
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from common import codec, keys
from common import messages as m
from common.mcap_file import RecordWriter
from common.names import AlgorithmName
from services.experiment.cli import main
from services.experiment.gantry import gantry_for, make_lab, run
from services.gantry.cycle import AFTER_REPORT_S, WRITE_MARGIN_S
from services.gantry.frames import OpenCvFrames
from services.gantry.settings import GantrySettings
from tests.conftest import wait_for
from tests.video import marker_video


def _path_csv(tmp_path: Path) -> Path:
    t = np.arange(0, 12.01, 0.5)
    path = tmp_path / "path.csv"
    path.write_text("t,x,y\n" + "\n".join(f"{ti},{-600 + 80 * ti},{200 * np.sin(ti / 3)}"
                                            for ti in t) + "\n")
    return path


def test_a_custom_path_runs_every_algorithm_with_plots(tmp_path: Path, crater_file: Path,
                                                       capsys) -> None:  # noqa: ANN001
    code = main(["gantry", "--scenario", "locomotive", "--trajectory", str(_path_csv(tmp_path)),
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


def _recording(path: Path, rows: list[tuple[float, float, float]], truth: bool) -> None:
    with path.open("wb") as f:
        writer = RecordWriter(f)
        for t, x, y in rows:
            if truth:
                key = keys.TRUTH_ROBOT.key(keys.DEFAULT_PREFIX, robot="walker")
                msg: m.Message = m.RobotTruth(measured_s=t, robot="walker", x_mm=x, y_mm=y,
                                              z_mm=0.0, vx_mm_s=0.0, vy_mm_s=0.0)
            else:
                key = keys.TRACKER_ROBOT.key(keys.DEFAULT_PREFIX)
                msg = m.RobotPosition(measured_s=t, x_mm=x, y_mm=y, z_mm=0.0, vx_mm_s=0.0,
                                      vy_mm_s=0.0, vz_mm_s=0.0)
            writer.write(key, codec.encode(msg), encoding="msgpack", model=type(msg).__name__,
                         received_s=t, measured_s=t)
        writer.finish()


@pytest.mark.parametrize("truth", [True, False])
def test_a_recorded_run_is_replayed_through_the_gantry(tmp_path: Path, crater_file: Path,
                                                       capsys, truth: bool) -> None:  # noqa: ANN001
    start = 1.7e9
    rows = [(start + t, -500 + 60 * t, 100 * np.sin(t / 2)) for t in np.arange(0, 15, 0.05)]
    recording = tmp_path / "run.mcap"
    _recording(recording, rows, truth)
    assert main(["gantry", "--recording", str(recording), "--algorithm", "basic",
                 "--crater", str(crater_file), "--json"]) == 0
    (result,) = json.loads(capsys.readouterr().out)["results"]
    assert result["sim_s"] == pytest.approx(15.0, abs=0.3), "the recorded path's length"
    assert result["rms_mm"] < 80.0, result


def test_a_recording_without_a_robot_is_named(tmp_path: Path, crater_file: Path,
                                               capsys) -> None:  # noqa: ANN001
    recording = tmp_path / "empty.mcap"
    with recording.open("wb") as f:
        RecordWriter(f).finish()
    assert main(["gantry", "--recording", str(recording), "--crater", str(crater_file)]) == 2
    assert "no robot path" in capsys.readouterr().err


@pytest.mark.parametrize(("content", "message"), [
    ("t,x\n0,1\n1,2\n", "header must be t,x,y"),
    ("t,x,y\n0,1,2\n", "≥ 2 rows"),
    ("t,x,y\n0,1,2\n0,3,4\n", "increasing t"),
    ("", "empty"),
    ("t,x,y\n", "≥ 2 rows"),
    ("t,x,y\n0,1e12,0\n1,-1e12,0\n", "leaves the gantry's workspace (x -3000…3000"),
])
def test_a_bad_trajectory_file_is_named(tmp_path: Path, crater_file: Path, capsys,  # noqa: ANN001
                                        content: str, message: str) -> None:
    path = tmp_path / "bad.csv"
    path.write_text(content)
    assert main(["gantry", "--trajectory", str(path), "--algorithm", "basic",
                 "--crater", str(crater_file)]) == 2
    err = capsys.readouterr().err
    assert message in err and str(path) in err, err


def test_the_lab_files_gantry_settings_are_the_ones_run(tmp_path: Path, crater_file: Path,
                                                        capsys) -> None:  # noqa: ANN001
    """No oracle: the guard's limits are the lab's, not the sim crane's."""
    path = _path_csv(tmp_path)
    args = ["gantry", "--trajectory", str(path), "--algorithm", "basic", "--crater",
            str(crater_file), "--json"]
    assert main(args) == 0
    free = json.loads(capsys.readouterr().out)["results"][0]
    lab = tmp_path / "lab.toml"
    lab.write_text("[gantry]\nmax_speed_mm_s = 20.0\n")  # far below the path's 80 mm/s
    assert main([*args, "--lab", str(lab)]) == 0
    slow = json.loads(capsys.readouterr().out)["results"][0]
    assert slow["rms_mm"] > 3 * free["rms_mm"], (free, slow)
    lab.write_text("[gantry]\nmax_speed_mm_s = -1\n")
    assert main([*args, "--lab", str(lab)]) == 2
    assert "gantry.max_speed_mm_s" in capsys.readouterr().err


def test_the_lab_files_default_filter_is_the_one_run(tmp_path: Path, crater_file: Path,
                                                     capsys) -> None:  # noqa: ANN001
    """``[gantry.default_filter]`` reaches ``default``'s filter: a filter that believes its
    measurements a thousand times less follows the path later, so farther behind."""
    args = ["gantry", "--trajectory", str(_path_csv(tmp_path)), "--algorithm", "default",
            "--crater", str(crater_file), "--json"]
    assert main(args) == 0
    as_shipped = json.loads(capsys.readouterr().out)["results"][0]
    lab = tmp_path / "lab.toml"
    lab.write_text("[gantry.default_filter]\nmeasurement_noise_mm = 800.0\n"
                   "accels_mm_s2 = [5.0, 10.0]\nbursts_s = [0.0, 0.0]\n")
    assert main([*args, "--lab", str(lab)]) == 0
    sluggish = json.loads(capsys.readouterr().out)["results"][0]
    assert sluggish["rms_mm"] > 1.5 * as_shipped["rms_mm"], (as_shipped, sluggish)
    for text, field in (("stay = 1.0", "gantry.default_filter.stay"),
                        ("accels_mm_s2 = [0, 10]", "gantry.default_filter.accels_mm_s2"),
                        ("bursts_s = [0.2]", "gantry.default_filter"),
                        ("noise_mm = 3", "gantry.default_filter.noise_mm")):
        lab.write_text(f"[gantry.default_filter]\n{text}\n")
        assert main([*args, "--lab", str(lab)]) == 2
        assert field in capsys.readouterr().err


def test_help_explains_the_commands(capsys) -> None:  # noqa: ANN001
    assert main([]) == 2
    out = capsys.readouterr().out
    assert "gantry" in out and "identify" in out
    with pytest.raises(SystemExit) as done:
        main(["gantry", "--help"])
    assert done.value.code == 0
    assert "--recording" in capsys.readouterr().out


def test_runs_are_reproducible_from_the_seed(crater_file: Path) -> None:
    settings = gantry_for(GantrySettings(), "pf-position", seed=3, marker_height_mm=350.0)
    results = [run(make_lab("walker", 3, crater_file), settings, end_s=15.0).summary()
               for _ in range(2)]
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


@pytest.mark.parametrize(("algorithm", "offset_s"), [("basic", AFTER_REPORT_S),
                                                   ("default", 0.25 - WRITE_MARGIN_S)])
def test_the_gantry_ticks_a_fixed_time_after_the_crane_reports(crater_file: Path,
                                                               algorithm: AlgorithmName,
                                                               offset_s: float) -> None:
    """The run starts out of step (its first tick 0.2 s after the controller's cycle) and,
    once the crane moves, settles at its offset after each report: the polls dithered, the
    phase found where their brackets overlap, the tick on time, not at the next poll (within
    the report's own age jitter and 4 ms)."""
    lab = make_lab("locomotive", 1, crater_file)
    settings = gantry_for(GantrySettings(), algorithm, seed=1, marker_height_mm=80.0)
    r = run(lab, settings, end_s=20.0)
    published_age = lab.settings.crane.report_latency_s
    jitter = lab.settings.crane.report_jitter_s
    settled = np.array(r.report_age_s[20:]) - published_age  # after 5 s
    assert np.all(np.abs(settled - offset_s) < jitter / 2 + 0.004), settled


def test_opencv_frames_from_a_video_file(tmp_path: Path) -> None:
    video = marker_video(tmp_path / "clip.avi", 10, (64, 48), (10, 20), 3)
    stop = threading.Event()
    source = OpenCvFrames(str(video), stop)
    try:
        frame = wait_for(source.take, timeout=5, period=0.01)
        assert frame is not None
        captured, image = frame
        assert image.shape == (48, 64) and image.dtype == np.uint8
        assert abs(captured - time.time()) < 5
    finally:
        stop.set()


def test_the_oracle_bound_runs_beside_the_algorithms(tmp_path: Path, crater_file: Path,
                                                     capsys) -> None:  # noqa: ANN001
    path = _path_csv(tmp_path)
    args = ["gantry", "--trajectory", str(path), "--crater", str(crater_file), "--json"]
    assert main([*args, "--algorithm", "oracle", "--ahead", "0.3", "0.5"]) == 0
    oracles = json.loads(capsys.readouterr().out)["results"]
    assert [r["algorithm"] for r in oracles] == ["oracle 0.30 s", "oracle 0.50 s"]
    assert main([*args, "--algorithm", "basic"]) == 0
    basic = json.loads(capsys.readouterr().out)["results"][0]
    assert min(r["rms_mm"] for r in oracles) < basic["rms_mm"], "knowing the path helps"


class _Terminal:
    """What the command writes to a terminal's stderr (it shows progress only there)."""

    def __init__(self) -> None:
        self.text = ""

    def write(self, text: str) -> int:
        self.text += text
        return len(text)

    def flush(self) -> None:
        pass

    def isatty(self) -> bool:
        return True


def test_progress_on_a_terminal_with_the_time_left_and_none_with_json(
        tmp_path: Path, crater_file: Path, monkeypatch, capsys) -> None:  # noqa: ANN001
    terminal = _Terminal()
    monkeypatch.setattr("sys.stderr", terminal)
    args = ["gantry", "--trajectory", str(_path_csv(tmp_path)), "--crater", str(crater_file),
            "--algorithm", "all"]
    assert main(args) == 0
    shown = terminal.text.split("\r\033[K")
    assert any(line.startswith("basic (1 of 5): 0 %") for line in shown)
    later = [line for line in shown if line.startswith("pf-position-gauss (3 of 5): ")]
    assert later and any("s left, about " in line and line.endswith("s for all")
                         for line in later)
    assert terminal.text.endswith("\r\033[K")  # the line is cleared before the results
    assert len(capsys.readouterr().out.strip().splitlines()) == 5  # the five results
    terminal.text = ""
    assert main([*args, "--json"]) == 0
    assert terminal.text == ""
