"""Pairing each picture with where the crane was when it was taken (services/gantry/crane_track.py,
cycle.py's report times, control.py's paired measurement): pure, on made-up clocks."""

from __future__ import annotations

import numpy as np
import pytest

from common.heightmap import HeightMap
from services.gantry.control import Controller, Fix
from services.gantry.crane_track import CraneTrack, MarkerTrack
from services.gantry.cycle import CycleSync
from services.gantry.settings import GantrySettings
from services.sim.render import Blob, draw
from tests.gantry.camera import CAMERA, pixel_of

GROUND_MM, MARKER_MM = 100.0, 80.0
FLAT = HeightMap(np.full((3, 3), GROUND_MM, np.float32), -5000, -5000, 5000)


def _constant_speed(t: float) -> tuple[np.ndarray, np.ndarray]:
    return np.array([-400.0 + 300.0 * t, 100.0 - 120.0 * t]), np.array([300.0, -120.0])


def _full_acceleration(t: float) -> tuple[np.ndarray, np.ndarray]:
    """From rest at 2,080 mm/s² (the identified crane's limit), then braking as hard."""
    a = np.array([2080.0, -900.0])
    if t < 0.3:
        return 0.5 * a * t * t, a * t
    top, v = 0.5 * a * 0.09, a * 0.3
    return top + v * (t - 0.3) - 0.5 * a * (t - 0.3) ** 2, v - a * (t - 0.3)


@pytest.mark.parametrize("motion", [_constant_speed, _full_acceleration])
def test_between_two_reports_the_crane_is_where_it_was(motion) -> None:  # noqa: ANN001
    """Hermite through the reports' positions and velocities: exact for any motion whose
    position is a polynomial up to the third degree between reports."""
    track = CraneTrack()
    for t in np.arange(0.0, 0.61, 0.25):
        track.add(t, *motion(t))
    for t in (0.05, 0.12, 0.2, 0.33, 0.49):
        paired = track.at(t)
        assert paired is not None and paired.extrapolated_s == 0.0
        start = 0.25 * np.floor(t / 0.25)
        if not (start < 0.3 < start + 0.25 and motion is _full_acceleration):  # a kink
            np.testing.assert_allclose(paired.xy_mm, motion(t)[0], atol=1e-6)


def test_after_the_newest_report_it_is_carried_on_and_flagged() -> None:
    track = CraneTrack()
    assert track.at(1.0) is None
    track.add(0.0, *_constant_speed(0.0))
    track.add(0.25, *_constant_speed(0.25))
    paired = track.at(0.31)
    assert paired is not None and paired.extrapolated_s == pytest.approx(0.06)
    np.testing.assert_allclose(paired.xy_mm, _constant_speed(0.31)[0])
    speeding = CraneTrack()
    for t in (0.0, 0.25):
        speeding.add(t, *_full_acceleration(t))
    paired = speeding.at(0.29)  # the last two reports' acceleration, carried on
    assert paired is not None
    np.testing.assert_allclose(paired.xy_mm, _full_acceleration(0.29)[0])
    track.add(0.2, np.zeros(2), np.zeros(2))  # older than the newest: not news
    assert track.newest is not None and track.newest.t_s == 0.25


def test_the_marker_track_interpolates_and_knows_its_gaps() -> None:
    marks = MarkerTrack(max_gap_s=0.1)
    assert marks.at(0.0, ahead_s=0.1) is None
    for t in (0.0, 0.025, 0.05, 0.3, 0.325):
        marks.add(t, _constant_speed(t)[0])
    paired = marks.at(0.04, ahead_s=0.1)
    assert paired is not None and paired.extrapolated_s == 0.0
    np.testing.assert_allclose(paired.xy_mm, _constant_speed(0.04)[0])
    np.testing.assert_allclose(paired.v_mm_s, [300.0, -120.0])
    assert marks.at(0.2, ahead_s=0.1) is None, "0.25 s without the marker: not seen then"
    ahead = marks.at(0.375, ahead_s=0.1)
    assert ahead is not None and ahead.extrapolated_s == pytest.approx(0.05)
    assert marks.at(0.5, ahead_s=0.1) is None


def test_a_report_is_timed_by_the_controllers_cycle() -> None:
    """The cycle it changed in, or — unchanged, standing — the last cycle a poll before."""
    sync = CycleSync(0.25)
    t, xy = 0.013, (0.0, 0.0)
    assert sync.published_s(t, sync.observe(t, xy), 0.025) == pytest.approx(t - 0.25), \
        "before the phase is known: at most a period ago"
    for cycle in range(1, 9):  # the controller publishes at 0.25 k + 0.1
        for poll in np.arange(0.0, 0.25, 0.025):
            t = cycle * 0.25 + poll + 0.013
            xy = (float(cycle if poll + 0.013 > 0.1 else cycle - 1), 0.0)
            changed = sync.observe(t, xy)
            published = sync.published_s(t, changed, 0.025)
            if changed or (cycle > 1 and poll + 0.013 > 0.125):
                assert published is not None
                assert abs(published - (cycle * 0.25 + 0.1)) < 0.013, (t, published)
    assert sync.published_s(2.5 + 0.113, False, 0.025) == pytest.approx(2.35, abs=0.013)


def _frame(robot_xy: np.ndarray, crane_xy: np.ndarray) -> np.ndarray:
    u, v, r = pixel_of(np.array([*robot_xy, GROUND_MM + MARKER_MM]), crane_xy)
    return draw([Blob(u, v, r, r)], CAMERA.width_px, CAMERA.height_px,
                np.random.default_rng(0), noise_sigma=0.0)


@pytest.mark.parametrize("motion", [_constant_speed, _full_acceleration])
@pytest.mark.parametrize("source", ["reports", "marker"])
def test_a_robot_standing_still_stays_still_while_the_crane_moves(motion, source: str
                                                                   ) -> None:  # noqa: ANN001
    """Pictures taken as the crane moves, handed over at the 4 Hz ticks with the crane's
    latest report (measured 0.05 s before it came): paired with the crane's position when
    each was taken, the robot stands where it stands; eq. 8 with the latest report instead
    (the paper's algorithms) sees it wander by the crane's speed times the picture's age."""
    robot = np.array([150.0, -60.0])
    settings = GantrySettings(marker_height_mm=MARKER_MM, report_age_s=0.05)
    paired = Controller(settings, FLAT)
    paper = Controller(settings.model_copy(update={"algorithm": "basic"}), FLAT)
    found: list[np.ndarray] = []
    wandered: list[float] = []
    frames = [(t, _frame(robot, motion(t)[0])) for t in np.arange(0.0, 0.6, 0.04)]
    for tick in (0.125, 0.375, 0.625):
        for report in np.arange(0.0, tick - 0.05 + 1e-9, 0.25):
            paired.track.add(report, *motion(report))
        for t in np.arange(0.0, tick, 0.02):
            if source == "marker":
                paired.marker_track.add(t, motion(t)[0])
        latest = motion(max(r for r in np.arange(0.0, tick, 0.25) if r <= tick - 0.05))[0]
        batch = [f for f in frames if tick - 0.25 <= f[0] < tick - 0.04][::-1]
        step = paired.step(tick, batch[0], latest, older=batch[1:])
        assert step.measured_xyz is not None
        found.append(step.measured_xyz[:2])
        old = paper.step(tick, batch[0], latest, older=batch[1:])
        assert old.measured_xyz is not None
        wandered.append(float(np.hypot(*(old.measured_xyz[:2] - robot))))
    assert max(np.hypot(*(f - robot)) for f in found) < 3.0, found
    assert max(wandered) > 15.0, "the paper's eq. 8 on a moving crane: the test can tell"


def test_the_motion_captures_fix_is_compared_at_the_pictures_time() -> None:
    """A robot walking at 200 mm/s, the motion capture's fix 0.2 s older than the picture:
    carried to the picture's time with its velocity, it agrees."""
    robot_at = lambda t: np.array([200.0 * t, 0.0])  # noqa: E731
    control = Controller(GantrySettings(marker_height_mm=MARKER_MM), FLAT)
    crane = np.zeros(2)
    control.track.add(0.0, crane, np.zeros(2))
    control.track.add(0.98, crane, np.zeros(2))
    fix = Fix(0.8, robot_at(0.8), np.array([200.0, 0.0]))
    step = control.step(1.05, (1.0, _frame(robot_at(1.0), crane)), crane, fix)
    assert step.measured_xyz is not None and step.disagreement == ""
    assert control.tracking_check.off_mm is not None and control.tracking_check.off_mm < 5.0
