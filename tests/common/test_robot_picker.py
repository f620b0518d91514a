"""Picking the robot marker and estimating its velocity."""

from __future__ import annotations

import numpy as np

from common.robot_picker import RobotPicker, Seen, SlidingSlope
from common.volume import Volume


def _frames(rng: np.random.Generator, seconds: float = 3.0, hz: float = 100.0):
    """A robot (id 7) at 200 mm/s in x, two static markers (ids 1, 2), 0.5 mm noise."""
    for n in range(int(seconds * hz)):
        t = n / hz
        robot = np.array([200.0 * t, 50.0, 100.0]) + rng.normal(0, 0.5, 3)
        yield t, [Seen.at("", 1, np.array([1000.0, 0, 0]) + rng.normal(0, 0.5, 3)),
                  Seen.at("", 2, np.array([-800.0, 300, 20]) + rng.normal(0, 0.5, 3)),
                  Seen.at("", 7, robot)]


def test_unlabelled_robot_is_the_moving_marker(rng: np.random.Generator) -> None:
    picker = RobotPicker()
    results = [picker.update(t, seen) for t, seen in _frames(rng)]
    assert results[3] is None, "nothing is taken before it has been seen moving"
    assert results[10] is not None, "20 mm of motion: taken"
    assert picker.chosen == 7
    last = results[-1]
    assert last is not None
    position, velocity = last
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
        out = picker.update(3.0 + n / 100, [Seen.at("", 1, np.array([1000.0, 0, 0])),
                                            Seen.at("", 7, stopped + rng.normal(0, 0.5, 3))])
    assert picker.chosen == 7 and out is not None
    assert np.linalg.norm(out[1]) < 30


def test_labelled_robot_and_bad_positions(rng: np.random.Generator) -> None:
    picker = RobotPicker(label="robot", volume=Volume(x_max_mm=3000))
    good = [Seen.at("robot", 0, np.array([10.0, 20.0, 30.0])), Seen.at("static_1", 0, np.zeros(3))]
    taken = picker.update(0.0, good)
    assert taken is not None and np.allclose(taken[0], [10, 20, 30])
    assert picker.update(0.01, [Seen.at("robot", 0, np.array([np.nan, 0, 0]))]) is None
    assert picker.update(0.02, [Seen.at("robot", 0, np.array([9000.0, 0, 0]))]) is None
    assert picker.update(0.03, [Seen.at("static_1", 0, np.zeros(3))]) is None


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


def _least_squares(samples: list[tuple[float, float, float, float]]) -> np.ndarray:
    array = np.array(samples)
    times = array[:, 0] - array[:, 0].mean()
    return times @ (array[:, 1:] - array[:, 1:].mean(axis=0)) / (times @ times)


def test_the_sliding_slope_is_the_least_squares_fit_of_its_window(
        rng: np.random.Generator) -> None:
    """Running sums against a fit of the window from scratch: at QTM's rate with jitter, across
    re-bases, on the wall clock's seconds (1.7e9), with gaps that empty the window."""
    slope, t, pushed = SlidingSlope(0.1), 1.7e9, []
    for n in range(3500):
        t += 0.001 + rng.uniform(0, 0.0002) + (0.3 if n in (1200, 2500) else 0.0)
        sample = (t, 5000.0 * np.sin(t), -4000.0 + 290.0 * (t - 1.7e9), rng.normal(0, 0.5))
        slope.push(sample)
        pushed.append(sample)
        window = [s for s in pushed if t - s[0] <= 0.1]
        found = slope.slope()
        if len(window) < 3:
            assert found is None
        else:
            assert found is not None
            np.testing.assert_allclose(found, _least_squares(window), rtol=1e-6, atol=1e-6)
    assert slope.REBASE_EVERY < 3500


def test_velocity_at_qtms_full_rate_with_an_occlusion(rng: np.random.Generator) -> None:
    picker = RobotPicker(label="robot")
    for n in range(2000):
        t = 1.7e9 + n / 1000
        if 1000 <= n < 1400:  # lost by QTM for 0.4 s
            continue
        xyz = np.array([290.0 * (t - 1.7e9), 30.0, 100.0]) + rng.normal(0, 0.5, 3)
        out = picker.update(t, [Seen.at("robot", 0, xyz)])
        assert out is not None
        if n == 1400:  # back: bridged over the occlusion with the last three samples
            np.testing.assert_allclose(out[1], [290.0, 0.0, 0.0], atol=40.0)
    assert out is not None
    np.testing.assert_allclose(out[1], [290.0, 0.0, 0.0], atol=25.0)

