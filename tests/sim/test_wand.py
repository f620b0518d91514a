"""The wand's carrier (pure, on given times): into the picture of a camera in calibration mode
at whatever zoom, over the crater otherwise; a continuous path that can be looked back on."""

from __future__ import annotations

import numpy as np

from common.camera import Pose, project
from common.ptz_lens import PtzLens, ZoomCurve, axis_215_px
from services.sim.wand import WandCarrier

MOUNT = Pose(3550.0, 1090.0, 2190.0, 180.0, 30.0, 165.0)
LENS = PtzLens(ZoomCurve((1, 6000, 9999), (3.8, 9.0, 46.0)).scaled(axis_215_px(1.0)),
               (axis_215_px(3.8), axis_215_px(46.0)),
               ((-0.3, 0.1, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0, 0.0)))


def _carrier(views: list, seed: int = 0) -> WandCarrier:
    return WandCarrier(np.random.default_rng(seed), lambda r: np.array([*r.uniform(-1500, 1500, 2),
                                                                       600.0]),
                       lambda _t: views, lambda _x, _y: 0.0, start_mm=np.array([0.0, 0.0, 500.0]))


def _dwells(carrier: WandCarrier, until_s: float) -> list[np.ndarray]:
    """The wand's position in the middle of each time it is held still."""
    held = []
    t = 0.0
    while t < until_s:
        if not np.any(carrier.velocity(t)):
            held.append(carrier.position(t))
            while t < until_s and not np.any(carrier.velocity(t)):
                t += 0.05
        t += 0.05
    return held


def test_at_the_longest_zoom_every_point_is_in_the_picture() -> None:
    intr = LENS.intrinsics(9999)
    carrier = _carrier([(MOUNT, intr)])
    points = np.array(_dwells(carrier, 60.0))[1:]  # the first: where it stood at the start
    assert len(points) >= 15
    uv = project(points, MOUNT, intr)
    inside = (uv[:, 0] >= 0) & (uv[:, 0] < 704) & (uv[:, 1] >= 0) & (uv[:, 1] < 576)
    assert inside.all()
    depth = np.linalg.norm(points - MOUNT.position, axis=1)
    assert np.ptp(depth) > 1000, "spread in depth, so that focal length and distance part"
    assert np.all(points[:, 2] >= 150.0), "above the floor"


def test_at_the_widest_zoom_the_points_reach_the_pictures_corners() -> None:
    intr = LENS.intrinsics(1)
    uv = project(np.array(_dwells(_carrier([(MOUNT, intr)]), 300.0))[1:], MOUNT, intr)
    corners = [(u < 704 * 0.2 or u > 704 * 0.8) and (v < 576 * 0.2 or v > 576 * 0.8)
               for u, v in uv]
    assert sum(corners) >= 3


def test_the_corners_are_taken_in_turn() -> None:
    """A person goes round the picture's corners, not by dice (a corner left out for minutes
    held a collection up)."""
    intr = LENS.intrinsics(1)
    points = np.array(_dwells(_carrier([(MOUNT, intr)], seed=5), 600.0))[1:]
    uv = project(points, MOUNT, intr)
    corner = [(int(u > 352), int(v > 288)) for u, v in uv
              if min(u, 704 - u) < 0.12 * 704 and min(v, 576 - v) < 0.12 * 576]
    assert len(corner) >= 20
    for i in range(len(corner) - 5):  # each corner within any six in a row (four in turn,
        assert len(set(corner[i:i + 6])) == 4, corner[i:i + 6]  # some points near one anyway)


def test_without_a_camera_in_calibration_mode_it_wanders_over_the_crater() -> None:
    points = np.array(_dwells(_carrier([]), 60.0))
    assert len(points) >= 5 and np.all(points[1:, 2] == 600.0)


def test_the_path_is_continuous_and_can_be_looked_back_on() -> None:
    carrier = _carrier([(MOUNT, LENS.intrinsics(4000))], seed=3)
    times = np.arange(0.0, 30.0, 0.01)
    path = np.array([carrier.position(t) for t in times])
    step = np.linalg.norm(np.diff(path, axis=0), axis=1)
    assert step.max() <= 600.0 * 0.01 + 1e-6  # never faster than its speed
    again = np.array([carrier.position(t) for t in times[-500:]])  # a look back
    np.testing.assert_array_equal(again, path[-500:])
    velocity = np.array([carrier.velocity(t) for t in times])
    steady = np.all(velocity[:-1] == velocity[1:], axis=1)  # not across a stop or a start
    assert steady.mean() > 0.9 and np.any(velocity[:-1][steady])
    np.testing.assert_allclose(path[:-1][steady] + velocity[:-1][steady] * 0.01,
                               path[1:][steady], atol=1e-6)
