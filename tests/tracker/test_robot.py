"""Picking the robot marker and estimating its velocity."""

from __future__ import annotations

import numpy as np

from common.volume import Volume
from services.tracker.robot import RobotPicker, Seen


def _frames(rng: np.random.Generator, seconds: float = 3.0, hz: float = 100.0):
    """A robot (id 7) at 200 mm/s in x, two static markers (ids 1, 2), 0.5 mm noise."""
    for n in range(int(seconds * hz)):
        t = n / hz
        robot = np.array([200.0 * t, 50.0, 100.0]) + rng.normal(0, 0.5, 3)
        yield t, [Seen("", 1, np.array([1000.0, 0, 0]) + rng.normal(0, 0.5, 3)),
                  Seen("", 2, np.array([-800.0, 300, 20]) + rng.normal(0, 0.5, 3)),
                  Seen("", 7, robot)]


def test_unlabelled_robot_is_the_moving_marker(rng: np.random.Generator) -> None:
    picker = RobotPicker()
    results = [picker.update(t, seen) for t, seen in _frames(rng)]
    assert results[3] is None, "nothing is taken before it has been seen moving"
    assert results[10] is not None, "20 mm of motion: taken"
    assert picker.chosen == 7
    position, velocity = results[-1]
    assert abs(position[0] - 200.0 * 2.99) < 3
    np.testing.assert_allclose(velocity, [200.0, 0.0, 0.0], atol=25.0)


def test_a_static_marker_is_never_taken(rng: np.random.Generator) -> None:
    picker = RobotPicker()
    for t, seen in _frames(rng):
        assert picker.update(t, seen[:2]) is None
    assert picker.chosen is None


def test_the_robot_is_kept_when_it_stops(rng: np.random.Generator) -> None:
    picker = RobotPicker()
    for t, seen in _frames(rng):
        picker.update(t, seen)
    stopped = np.array([600.0, 50.0, 100.0])
    for n in range(300):
        out = picker.update(3.0 + n / 100, [Seen("", 1, np.array([1000.0, 0, 0])),
                                            Seen("", 7, stopped + rng.normal(0, 0.5, 3))])
    assert picker.chosen == 7 and out is not None
    assert np.linalg.norm(out[1]) < 30


def test_labelled_robot_and_bad_positions(rng: np.random.Generator) -> None:
    picker = RobotPicker(label="robot", volume=Volume(x_max_mm=3000))
    good = [Seen("robot", 0, np.array([10.0, 20.0, 30.0])), Seen("static_1", 0, np.zeros(3))]
    assert np.allclose(picker.update(0.0, good)[0], [10, 20, 30])
    assert picker.update(0.01, [Seen("robot", 0, np.array([np.nan, 0, 0]))]) is None
    assert picker.update(0.02, [Seen("robot", 0, np.array([9000.0, 0, 0]))]) is None
    assert picker.update(0.03, [Seen("static_1", 0, np.zeros(3))]) is None


def test_velocity_survives_a_short_occlusion(rng: np.random.Generator) -> None:
    picker = RobotPicker()
    frames = list(_frames(rng))
    for n, (t, seen) in enumerate(frames):
        if 150 <= n < 180:  # the robot marker is lost for 0.3 s
            seen = seen[:2]
        out = picker.update(t, seen)
        if n == 180:
            assert out is not None
            np.testing.assert_allclose(out[1], [200.0, 0.0, 0.0], atol=40.0)
