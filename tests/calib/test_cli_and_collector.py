"""``stb calib solve`` from files, and the collector's pairing rules (pure)."""

from __future__ import annotations

import json
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from common import messages as m
from common.camera import Pose, project
from common.passpoint_collector import Collector
from common.passpoints import Passpoints, format_passpoints, read_passpoints, write_passpoints
from common.ptz_lens import axis_215, axis_215_px
from services.calib.solve_cli import main
from services.calib.synthetic import (
    PAPER_GUESS,
    PAPER_POSE,
    moving_marker,
    passpoints,
    zoom_passpoints,
)
from tests.calib.test_solve import errors
from tests.calib.test_zoom_fit import drawn_lens
from tests.conftest import ROOT, wait_for


def _write_track(path: Path, times: np.ndarray, xyz: np.ndarray) -> None:
    rows = "\n".join(f"{t:.6f},{x:.3f},{y:.3f},{z:.3f}" for t, (x, y, z) in zip(times, xyz,
                                                                                strict=True))
    path.write_text("t,X,Y,Z\n" + rows + "\n")


def test_solve_cli_prints_the_promised_json_and_plots(tmp_path: Path, capsys) -> None:  # noqa: ANN001
    points, wrong = passpoints(PAPER_POSE, np.random.default_rng(4), wrong_fraction=0.05)
    csv = tmp_path / "pp.csv"
    write_passpoints(csv, points)
    initial = ",".join(str(v) for v in (*PAPER_GUESS.position, PAPER_GUESS.rx_deg,
                                        PAPER_GUESS.ry_deg, PAPER_GUESS.rz_deg))
    code = main([str(csv), "--initial", initial, "--method", "cmaes", "--plot",
                 str(tmp_path / "plots"), "--json"])
    report = json.loads(capsys.readouterr().out)
    assert code == 0
    assert set(report) >= {"position_mm", "orientation_deg", "mean_error_px", "evaluations",
                           "seconds", "inliers", "focal_px"}
    assert "time_offset_s" not in report, "only when a track is given"
    assert report["rejected"] == wrong.tolist()
    from common.camera import Pose

    fitted = Pose(*report["position_mm"], *report["orientation_deg"])
    assert errors(fitted, PAPER_POSE)[0] < 10.0
    for name in ("fitness.png", "residuals.png"):
        assert (tmp_path / "plots" / name).read_bytes()[:4] == b"\x89PNG"


def test_solve_cli_with_a_track_and_a_fitted_focal_length(tmp_path: Path, capsys) -> None:  # noqa: ANN001
    points, track = moving_marker(PAPER_POSE, np.random.default_rng(1), count=150,
                                  speed_mm_s=800.0, offset_s=0.1)
    csv, track_csv = tmp_path / "pp.csv", tmp_path / "track.csv"
    csv.write_text(format_passpoints(points))
    _write_track(track_csv, track.times_s, track.xyz_mm)
    assert main([str(csv), "--mocap-track", str(track_csv), "--fit-focal", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert abs(report["time_offset_s"] - 0.1) < 0.01
    assert abs(report["focal_px"] / axis_215_px(3.8) - 1) < 0.02


@pytest.mark.parametrize(("content", "args", "code", "message"), [
    ("X,Y,u,v\n1,2,3,4\n", [], 2, "lacks Z"),
    ("X,Y,Z,u,v\n1,2,3,4,five\n", [], 2, "row 2"),
    ("X,Y,Z,u,v\n1,2,3,4,5\n", [], 3, "at least 6"),
    ("X,Y,Z,u,v\n1,2,3,4,5\n", ["--initial", "1,2,3"], 2, "six numbers"),
    ("X,Y,Z,u,v\n1,2,3,4,5\n", ["--mocap-track", "/nonexistent.csv"], 2, "cannot read"),
])
def test_solve_cli_errors_name_the_problem(tmp_path: Path, capsys, content: str,  # noqa: ANN001
                                           args: list[str], code: int, message: str) -> None:
    csv = tmp_path / "pp.csv"
    csv.write_text(content)
    assert main([str(csv), *args]) == code
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_solve_cli_measures_the_lens_from_a_file_of_several_zooms(tmp_path: Path,
                                                                   capsys) -> None:  # noqa: ANN001
    """The zoom column round-trips through the CSV; the file alone gives the lens."""
    rng = np.random.default_rng(7)
    truth = drawn_lens(rng)
    sets = zoom_passpoints(PAPER_POSE, truth, [1, 5000, 8000, 9999], rng, count=50)
    joined = Passpoints.joined({s.zoom: Passpoints(s.world_mm, s.pixels) for s in sets})
    csv = tmp_path / "passpoints.csv"
    write_passpoints(csv, joined)
    again = read_passpoints(csv)
    assert again.zooms is not None and sorted(again.by_zoom()) == [1, 5000, 8000, 9999]
    np.testing.assert_allclose(again.pixels, joined.pixels, atol=1e-3)
    assert main([str(csv), "--json", "--plot", str(tmp_path / "plots")]) == 0
    report = json.loads(capsys.readouterr().out)
    assert [at["zoom"] for at in report["lens"]] == [1, 5000, 8000, 9999]
    for at in report["lens"]:
        assert at["focal_px"] == pytest.approx(truth.focal_px(at["zoom"]), rel=0.01)
    assert errors(Pose(*report["position_mm"], *report["orientation_deg"]),
                  PAPER_POSE)[0] < 10.0
    assert (tmp_path / "plots" / "lens.png").stat().st_size > 10_000
    assert main([str(csv)]) == 0 and "9999" in capsys.readouterr().out  # the table


def test_a_zoom_that_is_no_step_is_named(tmp_path: Path, capsys) -> None:  # noqa: ANN001
    csv = tmp_path / "pp.csv"
    csv.write_text("X,Y,Z,u,v,zoom\n1,2,3,4,5,1\n1,2,3,4,5,2.5\n")
    assert main([str(csv)]) == 2
    assert "rows 3" in capsys.readouterr().err


def test_collect_names_bad_zooms_before_asking_anyone() -> None:
    for bad in ("1", "1,x", "1,1", "0,500", "1,20000"):
        done = subprocess.run([sys.executable, "-m", "services.cli", "calib", "collect",
                               "--camera", "ptz1", "--zooms", bad], cwd=ROOT,
                              capture_output=True, text=True, timeout=30)
        assert done.returncode == 2 and "--zooms" in done.stderr, (bad, done.stderr)


# --- the collector -----------------------------------------------------------------------------

STATIC_PX = (120.0, 80.0)


def _frame(t: float, wand: np.ndarray | None) -> m.MarkerFrame:
    markers = [m.Marker(label="static_1", x_mm=0.0, y_mm=0.0, z_mm=0.0)]
    if wand is not None:
        markers.append(m.Marker(label="wand", x_mm=wand[0], y_mm=wand[1], z_mm=wand[2]))
    return m.MarkerFrame(measured_s=t, frame=int(t * 100), markers=markers)


def _detections(t: float, spots: list[tuple[float, float]]) -> m.MarkerDetections:
    return m.MarkerDetections(
        measured_s=t, camera="ptz1", status="ok", threshold=230, width_px=704, height_px=576,
        markers=[m.DetectedMarker(u_px=u, v_px=v, radius_long_px=3, radius_short_px=3,
                                  angle_deg=0, roundness=1.0, area_px=28) for u, v in spots])


def test_collector_interpolates_the_wand_and_ignores_what_stays_put() -> None:
    intr = axis_215(3.8)
    collector = Collector(target=1000, marker_label="wand", min_spacing_mm=50.0)

    def wand_at(t: float) -> np.ndarray:  # 500 mm/s along a slanted line in view
        return np.array([-1000.0 + 300 * t, -800.0 + 400 * t, 300.0 + 50 * t])

    reasons = []
    for i in range(800):  # mocap at 100 Hz, a snapshot every 0.1 s (+ 37 ms)
        t = i / 100
        collector.on_frame(_frame(t, wand_at(t)))
        if i % 10 == 0 and i > 10:
            shot = t - 0.063
            wand_px = project(wand_at(shot)[None, :], PAPER_POSE, intr)[0]
            reasons.append(collector.on_detections(_detections(
                shot, [STATIC_PX, (float(wand_px[0]), float(wand_px[1]))])))
    assert reasons[:4] == ["too many"] * 4, "until a spot has stood still while the wand moved"
    accepted = [r for r in reasons if r is None]
    assert len(accepted) >= len(reasons) - 10
    points = collector.passpoints()
    assert points.times_s is not None
    for t, xyz in zip(points.times_s, points.world_mm, strict=True):
        assert np.allclose(xyz, wand_at(t), atol=1e-6), "interpolated at the capture time"
    assert collector.on_detections(_detections(7.9, [STATIC_PX])) == "no marker"
    assert collector.on_detections(_detections(20.0, [(300.0, 300.0)])) == \
        "marker not in mocap"
    assert isinstance(collector.passpoints(), Passpoints)


def test_a_reflection_that_flickers_is_left_out_as_one_that_stays() -> None:
    """A reflection at the threshold (or the picture's edge) shows in every other snapshot
    only: it stays put while the wand moves, so it is not the wand."""
    intr = axis_215(3.8)
    collector = Collector(target=1000, marker_label="wand", min_spacing_mm=50.0)

    def wand_at(t: float) -> np.ndarray:
        return np.array([-1000.0 + 300 * t, -800.0 + 400 * t, 300.0 + 50 * t])

    reasons = []
    for i in range(800):
        t = i / 100
        collector.on_frame(_frame(t, wand_at(t)))
        if i % 10 == 0 and i > 10:
            shot = t - 0.063
            wand_px = project(wand_at(shot)[None, :], PAPER_POSE, intr)[0]
            spots = [(float(wand_px[0]), float(wand_px[1]))]
            if (i // 10) % 2 == 0:
                spots.append((STATIC_PX[0] + 0.7, STATIC_PX[1] - 0.5))
            reasons.append(collector.on_detections(_detections(shot, spots)))
    assert reasons[-40:].count(None) == 40, reasons[-40:]
    assert reasons.count("too many") <= 4


def test_a_snapshot_answered_later_than_usual_is_skipped_only_while_the_wand_moves() -> None:
    """The camera answers in about 40 ms; now and then a busy machine makes it 60 ms later:
    taken at 500 mm/s that is 30 mm of doubt (skipped, "late snapshot"); held still, none."""
    intr = axis_215(3.8)
    collector = Collector(target=1000, marker_label="wand", min_spacing_mm=1.0)
    rng = np.random.default_rng(3)

    def wand_at(t: float) -> np.ndarray:  # moves for 4 s at 500 mm/s, then stands 4 s
        moving = min(t, 4.0)
        return np.array([-1000.0 + 300 * moving, -800.0 + 400 * moving, 300.0])

    verdicts: list[tuple[float, bool, str | None]] = []
    for i in range(800):
        t = i / 100
        collector.on_frame(_frame(t, wand_at(t)))
        if i % 10 == 0 and i > 10:
            shot = t - 0.063
            late = i % 50 == 0
            answered = (0.1 if late else 0.04) + rng.uniform(-0.002, 0.002)
            wand_px = project(wand_at(shot)[None, :], PAPER_POSE, intr)[0]
            spots = [(float(wand_px[0]) + (i % 30) * 4.0, float(wand_px[1]))]  # not seen there
            msg = _detections(shot, spots).model_copy(update={"answered_after_s": answered})
            verdicts.append((shot, late, collector.on_detections(msg)))
    # judged once the camera's usual answer is known (five snapshots)
    moving = [(late, why) for shot, late, why in verdicts if 0.8 < shot < 3.9]
    still = [(late, why) for shot, late, why in verdicts if shot > 4.2]
    late_ones = [why for late, why in moving if late]
    assert len(late_ones) >= 5 and late_ones == ["late snapshot"] * len(late_ones)
    assert all(why is None for late, why in moving if not late)
    # standing, a late answer is no doubt (the rest are "not moved": the wand stands)
    assert any(late for late, _ in still) and "late snapshot" not in [why for _, why in still]
    assert collector.skipped["late snapshot"] == [why for *_, why in verdicts].count(
        "late snapshot")  # the progress line's count


def test_collector_skips_a_marker_that_has_not_moved() -> None:
    collector = Collector(target=10, marker_label="wand", min_spacing_mm=50.0)
    for i in range(300):
        collector.on_frame(_frame(i / 100, np.array([100.0, 200.0, 300.0 + (i > 200) * 80])))
    assert collector.on_detections(_detections(1.0, [(300.0, 300.0)])) is None
    assert collector.on_detections(_detections(1.5, [(300.0, 300.0)])) == "not moved"
    assert collector.on_detections(_detections(2.5, [(300.0, 310.0)])) is None
    assert collector.skipped == {"not moved": 1}


def test_collector_spreads_passpoints_over_the_picture() -> None:
    """A wand that moved in the world but shows where a passpoint was already taken is
    skipped: the count is not filled in one part of the picture."""
    collector = Collector(target=10, marker_label="wand", min_spacing_mm=50.0,
                          min_spacing_px=20.0)
    for i in range(400):
        collector.on_frame(_frame(i / 100, np.array([100.0 + i, 200.0, 300.0])))
    assert collector.on_detections(_detections(0.5, [(300.0, 300.0)])) is None
    assert collector.on_detections(_detections(1.5, [(330.0, 300.0)])) is None
    assert collector.on_detections(_detections(2.5, [(305.0, 310.0)])) == "seen there"
    assert collector.on_detections(_detections(3.5, [(300.0, 340.0)])) is None
    assert collector.skipped == {"seen there": 1}


def test_collector_with_coverage_is_done_only_when_every_cell_has_its_share() -> None:
    collector = Collector(target=2, marker_label="wand", coverage=(2, 1, 1))
    for i in range(400):
        collector.on_frame(_frame(i / 100, np.array([100.0 + i, 200.0, 300.0])))
    assert collector.on_detections(_detections(0.5, [(100.0, 300.0)])) is None
    assert collector.on_detections(_detections(1.5, [(200.0, 300.0)])) is None
    assert not collector.done and collector.uncovered() == ["right"]
    assert collector.on_detections(_detections(2.5, [(600.0, 300.0)])) is None
    assert collector.done and collector.uncovered() == []


def test_collector_with_corners_is_done_only_when_each_corner_has_its_share() -> None:
    collector = Collector(target=1, marker_label="wand", corners=(0.15, 1))
    for i in range(600):
        collector.on_frame(_frame(i / 100, np.array([100.0 + i, 200.0, 300.0])))
    for t, (u, v) in enumerate([(350.0, 300.0), (100.0, 50.0), (20.0, 30.0), (690.0, 20.0),
                                (10.0, 560.0)]):  # the second: near the top, not the corner
        assert collector.on_detections(_detections(t + 0.5, [(u, v)])) is None
    assert not collector.done and collector.uncovered() == ["bottom right corner"]
    assert collector.on_detections(_detections(5.5, [(650.0, 540.0)])) is None
    assert collector.done and collector.uncovered() == []


def test_a_binary_passpoint_file_is_named(tmp_path: Path, capsys) -> None:  # noqa: ANN001
    path = tmp_path / "pp.csv"
    path.write_bytes(b"\x89PNG\r\n\x1a\n\x00\xff\xfe")
    assert main([str(path)]) == 2
    err = capsys.readouterr().err
    assert str(path) in err and "not a CSV text file" in err and "Traceback" not in err


def _quiet_node() -> object:
    """What a session needs of its node: a stop event and a bus to publish on."""
    from types import SimpleNamespace

    return SimpleNamespace(stop=threading.Event(),
                           bus=SimpleNamespace(publish=lambda *args, **kwargs: None))


@pytest.mark.parametrize(("accept", "state"), [(True, "review"), (False, "discarded")])
def test_a_pose_held_for_review_waits_for_the_operators_word(tmp_path: Path, accept: bool,
                                                             state: str) -> None:
    """A calibration from the page: the solved pose is held (state review) until an
    operator accepts it (then it is taken) or discards it (the camera keeps its pose)."""
    from services.calib.session import Session
    from services.calib.settings import CalibSettings
    from services.calib.store import PoseStore

    session = Session(_quiet_node(), CalibSettings(), PoseStore(tmp_path), "ptz1", 100,  # type: ignore[arg-type]
                      60.0, lambda pose, report: None, review=True)
    assert not session.decide(accept=True), "nothing held yet"
    outcome: list[bool] = []
    waiting = threading.Thread(target=lambda: outcome.append(session._reviewed("12 passpoints")))
    waiting.start()
    wait_for(lambda: session.state == "review", timeout=5)
    assert "accept or discard" in session.message
    assert session.decide(accept=accept)
    waiting.join(5)
    assert outcome == [accept] and session.state == state


def test_a_pose_not_reviewed_in_time_is_discarded(tmp_path: Path) -> None:
    from services.calib.session import Session
    from services.calib.settings import CalibSettings
    from services.calib.store import PoseStore

    session = Session(_quiet_node(), CalibSettings(review_s=0.3), PoseStore(tmp_path), "ptz1",  # type: ignore[arg-type]
                      100, 60.0, lambda pose, report: None, review=True)
    assert session._reviewed("12 passpoints") is False
    assert session.state == "discarded" and "not accepted within 0.3 s" in session.message
