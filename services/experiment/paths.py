"""Robot paths to run the gantry experiment on: a CSV file, or a recorded run.

Both give a ``Trajectory`` of (x, y) over time (z is put on the crater by the experiment).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from common import codec, keys
from common import messages as m
from common.mcap_file import RecordingError, read_samples, recorded_keys
from services.sim.robots import Trajectory

MIN_SAMPLES = 2


def read_csv(path: Path) -> Trajectory:
    """A robot path from CSV ``t,x,y`` (s, mm)."""
    try:
        if not path.read_bytes().strip():
            raise ValueError(f"{path}: empty (expected a header t,x,y and rows)")
        data = np.genfromtxt(path, delimiter=",", names=True)
    except (OSError, ValueError) as err:
        raise ValueError(f"cannot read {path}: {err}") from err
    if data.dtype.names is None or not {"t", "x", "y"} <= set(data.dtype.names):
        raise ValueError(f"{path}: header must be t,x,y (got {data.dtype.names})")
    t, x, y = (np.atleast_1d(data[n]).astype(float) for n in ("t", "x", "y"))
    return _checked(path, t, x, y)


def read_recording(path: Path, prefix: str = keys.DEFAULT_PREFIX) -> Trajectory:
    """The robot's path in a recording: the sim's truth (``sim/truth/robot/*``) when it was
    recorded, else the tracker's robot position (``tracker/robot``, the motion capture)."""
    try:
        recorded = recorded_keys(path)
    except RecordingError as err:
        raise ValueError(str(err)) from err
    truth = sorted(k for k in recorded if keys.TRUTH_ROBOT.match(prefix, k) is not None)
    wanted, topic = ((truth[:1], keys.TRUTH_ROBOT) if truth else
                     ([keys.TRACKER_ROBOT.key(prefix)], keys.TRACKER_ROBOT))
    rows = []
    for sample in read_samples(path, wanted):
        try:
            msg = codec.decode(topic.model, sample.payload, max_bytes=topic.max_payload_bytes)
        except codec.DecodeError:
            continue  # a bad sample in a recording costs that sample only
        assert isinstance(msg, m.RobotPosition | m.RobotTruth)
        rows.append((msg.measured_s, msg.x_mm, msg.y_mm))
    if len(rows) < MIN_SAMPLES:
        raise ValueError(f"{path}: no robot path in it (needs {wanted[0]} or "
                         f"{keys.TRUTH_ROBOT.pattern(prefix)}; found "
                         f"{', '.join(sorted(recorded)) or 'nothing'})")
    t, x, y = np.array(sorted(rows)).T
    keep = np.concatenate([[True], np.diff(t) > 0])  # one sample per instant
    return _checked(path, t[keep] - t[0], x[keep], y[keep])


def _checked(path: Path, t: np.ndarray, x: np.ndarray, y: np.ndarray) -> Trajectory:
    if len(t) < MIN_SAMPLES or not np.all(np.isfinite([t, x, y])) or np.any(np.diff(t) <= 0):
        raise ValueError(f"{path}: needs ≥ 2 rows of finite numbers with increasing t")
    return Trajectory(path.stem, t, np.column_stack([x, y, np.zeros_like(x)]))


def check_workspace(path: Trajectory, source: Path, x_mm: tuple[float, float],
                    y_mm: tuple[float, float]) -> None:
    """ValueError naming the first point of ``path`` outside the crane's workspace: the crane
    cannot follow a robot there."""
    xy = path.xyz_mm[:, :2]
    outside = np.flatnonzero((xy[:, 0] < x_mm[0]) | (xy[:, 0] > x_mm[1])
                             | (xy[:, 1] < y_mm[0]) | (xy[:, 1] > y_mm[1]))
    if len(outside):
        i = int(outside[0])
        raise ValueError(f"{source}: the path leaves the gantry's workspace (x {x_mm[0]:g}…"
                         f"{x_mm[1]:g}, y {y_mm[0]:g}…{y_mm[1]:g} mm) at t = {path.t_s[i]:g} s: "
                         f"({xy[i, 0]:g}, {xy[i, 1]:g}) mm")
