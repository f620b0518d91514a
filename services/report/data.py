"""What a report is made of, read once from a recording: time series per topic, and the
figures computed from them (pure functions of those series)."""

from __future__ import annotations

import math
from collections import Counter, defaultdict, deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from common import codec, keys
from common import messages as m
from common.camera import Pose, head_pose, reprojection_px
from common.mcap_file import Sample, read_run
from common.passpoint_collector import Collector
from common.ptz_lens import intrinsics_of

STATE_MATCH_S = 0.5
"""A crane state is compared with the robot only if a robot sample lies this close."""
MOCAP_AHEAD_S = 0.05
ALARM_STATUSES = ("reacquiring", "stale", "fault", "stopped", "unreachable")
"""Crane statuses the report marks as moments of the run (with stills), when they begin."""
FRAMES_AROUND_S = 5.0
"""Mocap frames are kept (for the calibration residuals) only this close to a PTZ camera's
detections: a long run's 100 frames a second are not held in memory."""


@dataclass
class Series:
    """Times (s, measurement) and rows of values of one kind of message."""

    t: list[float] = field(default_factory=list)
    rows: list[tuple[float, ...]] = field(default_factory=list)

    def add(self, t: float, *values: float) -> None:
        self.t.append(t)
        self.rows.append(values)

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        order = np.argsort(self.t, kind="stable")
        t = np.asarray(self.t, dtype=float)[order]
        values = np.asarray(self.rows, dtype=float).reshape(len(self.t), -1)[order]
        return t, values

    def __len__(self) -> int:
        return len(self.t)


@dataclass
class Recording:
    """The decoded content of a recording that the report uses."""

    path: Path
    counts: Counter = field(default_factory=Counter)
    invalid: Counter = field(default_factory=Counter)
    first_s: float = float("inf")
    last_s: float = float("-inf")
    robot: Series = field(default_factory=Series)  # tracker: x, y, z, vx, vy
    truth: Series = field(default_factory=Series)  # sim truth: x, y
    crane: Series = field(default_factory=Series)  # gantry state: x, y, enabled
    estimate: Series = field(default_factory=Series)  # gantry: x, y, vx, vy, valid
    offload: Series = field(default_factory=Series)  # horizontal error, share %, loss %
    aim: dict[str, Series] = field(default_factory=lambda: defaultdict(Series))  # per camera
    ptz_state: dict[str, Series] = field(default_factory=lambda: defaultdict(Series))
    poses: dict[str, m.CameraPose] = field(default_factory=dict)
    algorithms: Counter = field(default_factory=Counter)
    health: dict[str, m.ServiceHealth] = field(default_factory=dict)
    frames: list[m.MarkerFrame] = field(default_factory=list)  # around detections only
    detections: dict[str, list[m.MarkerDetections]] = field(
        default_factory=lambda: defaultdict(list))
    alarms: list[tuple[float, str]] = field(default_factory=list)  # (when it began, what)
    _crane_status: str = ""
    _pulling: bool = False

    @property
    def duration_s(self) -> float:
        return max(0.0, self.last_s - self.first_s)


def read_recording(paths: Path | Sequence[Path], prefix: str = keys.DEFAULT_PREFIX
                   ) -> Recording:
    """Decode every sample the report uses, streaming through the file (or a split
    recording's parts, in order); invalid ones are counted, not fatal. Raises RecordingError
    for a file that is not a recording."""
    rec = Recording(paths if isinstance(paths, Path) else paths[0])
    recent: deque[Sample] = deque()  # mocap frames of the last FRAMES_AROUND_S, undecoded
    keep_until = -math.inf  # mocap frames are kept up to here (after a detection)
    for sample in read_run(paths):
        rec.counts[sample.key] += 1
        rec.first_s = min(rec.first_s, sample.received_s)
        rec.last_s = max(rec.last_s, sample.received_s)
        topic = keys.topic_for(prefix, sample.key)
        if topic is keys.TRACKER_MARKERS and sample.received_s > keep_until:
            recent.append(sample)
            while recent[0].received_s < sample.received_s - FRAMES_AROUND_S:
                recent.popleft()
            continue
        if topic is keys.PTZ_DETECTIONS:
            keep_until = sample.received_s + FRAMES_AROUND_S
            while recent:
                _decode_into(rec, keys.TRACKER_MARKERS, recent.popleft())
        if topic is not None:
            _decode_into(rec, topic, sample)
    return rec


def _decode_into(rec: Recording, topic: keys.Topic, sample: Sample) -> None:
    try:
        msg = codec.decode(topic.model, sample.payload, max_bytes=topic.max_payload_bytes)
    except codec.DecodeError as err:
        rec.invalid[f"{sample.key}: {err.reason}"] += 1
        return
    _take(rec, topic, msg)


def _take(rec: Recording, topic: keys.Topic, msg: m.Message) -> None:  # noqa: C901 - a dispatch
    t = msg.measured_s
    if isinstance(msg, m.RobotPosition):
        rec.robot.add(t, msg.x_mm, msg.y_mm, msg.z_mm, msg.vx_mm_s, msg.vy_mm_s)
    elif isinstance(msg, m.RobotTruth):
        rec.truth.add(t, msg.x_mm, msg.y_mm)
    elif isinstance(msg, m.CraneState):
        rec.crane.add(t, msg.x_mm, msg.y_mm, float(msg.enabled))
        if msg.status in ALARM_STATUSES and msg.status != rec._crane_status:
            rec.alarms.append((t, f"crane {msg.status}"))
        rec._crane_status = msg.status
    elif isinstance(msg, m.RobotEstimate):
        rec.estimate.add(t, msg.x_mm, msg.y_mm, msg.vx_mm_s, msg.vy_mm_s, float(msg.valid))
        rec.algorithms[msg.algorithm] += 1
    elif isinstance(msg, m.GravityOffload):
        rec.offload.add(t, msg.horizontal_error_mm, msg.horizontal_share_pct,
                        msg.vertical_loss_pct)
        if msg.warning and not rec._pulling:
            rec.alarms.append((t, f"sideways pull {msg.horizontal_share_pct:.1f} % (limit "
                                  f"{msg.warn_above_pct:g} %)"))
        rec._pulling = msg.warning
    elif isinstance(msg, m.PtzState):
        rec.ptz_state[msg.camera].add(t, msg.pan_deg, msg.tilt_deg, msg.zoom)
        if msg.status == "tracking":
            rec.aim[msg.camera].add(t, msg.aim_error_deg)
    elif isinstance(msg, m.CameraPose):
        rec.poses[msg.camera] = msg
    elif isinstance(msg, m.ServiceHealth):
        rec.health[f"{msg.service}/{msg.instance}"] = msg
    elif isinstance(msg, m.MarkerFrame):
        rec.frames.append(msg)
    elif topic is keys.PTZ_DETECTIONS and isinstance(msg, m.MarkerDetections):
        rec.detections[msg.camera].append(msg)


# --- figures ------------------------------------------------------------------------------------


def crane_error(rec: Recording) -> tuple[np.ndarray, np.ndarray]:
    """(t, [crane − robot x, y]) at every crane state while the crane was enabled, with the
    robot (mocap) interpolated to that time; states with no robot sample near are left out."""
    if len(rec.crane) == 0 or len(rec.robot) < 2:
        return np.empty(0), np.empty((0, 2))
    t, crane = rec.crane.arrays()
    rt, robot = rec.robot.arrays()
    near = np.abs(rt[np.clip(np.searchsorted(rt, t), 0, len(rt) - 1)] - t) <= STATE_MATCH_S
    keep = (crane[:, 2] > 0) & near & (t >= rt[0]) & (t <= rt[-1])
    t = t[keep]
    robot_xy = np.column_stack([np.interp(t, rt, robot[:, 0]), np.interp(t, rt, robot[:, 1])])
    return t, crane[keep, :2] - robot_xy


def moments(rec: Recording, most: int = 6, apart_s: float = 5.0) -> list[tuple[float, str]]:
    """The run's moments worth a picture, in time order: the largest crane error and the
    beginnings of alarms (at most ``most``, none within ``apart_s`` of one kept before)."""
    t, error = crane_error(rec)
    candidates = []
    if len(t):
        distance = np.hypot(error[:, 0], error[:, 1])
        worst = int(np.argmax(distance))
        candidates.append((float(t[worst]), f"largest crane error, {distance[worst]:.0f} mm"))
    candidates += rec.alarms
    kept: list[tuple[float, str]] = []
    for when, what in candidates:
        if len(kept) < most and all(abs(when - k) >= apart_s for k, _ in kept):
            kept.append((when, what))
    return sorted(kept)


def collect_again(frames: list[m.MarkerFrame], detections: list[m.MarkerDetections],
                  marker_label: str) -> Collector:
    """The calib service's passpoint collector run over recorded messages, in time order:
    each snapshot's detections once the mocap stream has passed its capture time."""
    collector = Collector(10**9, marker_label)
    frames = sorted(frames, key=lambda f: f.measured_s)
    i = 0
    for msg in sorted(detections, key=lambda d: d.measured_s):
        while i < len(frames) and frames[i].measured_s <= msg.measured_s + MOCAP_AHEAD_S:
            collector.on_frame(frames[i])
            i += 1
        collector.on_detections(msg)
    return collector


def calibration_residuals(rec: Recording, marker_label: str = "wand") -> dict[str, np.ndarray]:
    """Per camera with a recorded pose: every passpoint found in the recording (the calib
    collector run again over its mocap frames and detections) reprojected through that pose at
    the pan and tilt the camera reported then. Pixels."""
    out: dict[str, np.ndarray] = {}
    for camera, pose_msg in rec.poses.items():
        states = rec.ptz_state.get(camera)
        if not rec.detections.get(camera) or states is None or len(states) == 0:
            continue
        collector = collect_again(rec.frames, rec.detections[camera], marker_label)
        if not collector.times:
            continue
        points = collector.passpoints()
        if points.times_s is None:
            continue
        st, pan_tilt = states.arrays()
        mount = Pose.of(pose_msg)
        track = collector.track()
        world = track.at(points.times_s + pose_msg.time_offset_s) if track.covers(
            points.times_s + pose_msg.time_offset_s) else points.world_mm
        residuals = []
        for time_s, xyz, pixel in zip(points.times_s, world, points.pixels, strict=True):
            i = int(np.clip(np.searchsorted(st, time_s), 0, len(st) - 1))
            head = head_pose(mount, pan_tilt[i, 0], pan_tilt[i, 1])
            # through the measured lens at the zoom of the time; one zoom: the fitted focal
            intr = intrinsics_of(pose_msg, pan_tilt[i, 2])
            residuals.append(reprojection_px(head, xyz[None, :], pixel[None, :], intr)[0])
        out[camera] = np.array(residuals)
    return out


def summary(rec: Recording) -> dict[str, float | int | str | None]:
    """The run's figures for the HTML page (rounded; None where the recording has no data)."""
    _, error = crane_error(rec)
    distance = np.hypot(error[:, 0], error[:, 1]) if len(error) else np.empty(0)
    figures: dict[str, float | int | str | None] = {
        "duration_s": round(rec.duration_s, 1),
        "samples": int(sum(rec.counts.values())),
        "keys": len(rec.counts),
        "invalid_samples": int(sum(rec.invalid.values())),
        "gantry_algorithm": rec.algorithms.most_common(1)[0][0] if rec.algorithms else None,
        "crane_error_mean_mm": _round(distance.mean()) if len(distance) else None,
        "crane_error_p95_mm": _round(np.percentile(distance, 95)) if len(distance) else None,
        "crane_error_max_mm": _round(distance.max()) if len(distance) else None,
        "crane_error_std_x_mm": _round(error[:, 0].std()) if len(error) else None,
        "crane_error_std_y_mm": _round(error[:, 1].std()) if len(error) else None,
    }
    if len(rec.offload):
        _, off = rec.offload.arrays()
        figures["offload_share_max_pct"] = _round(off[:, 1].max(), 2)
        figures["offload_loss_max_pct"] = _round(off[:, 2].max(), 3)
    for camera, series in sorted(rec.aim.items()):
        _, aim = series.arrays()
        figures[f"{camera}_aim_error_median_deg"] = _round(np.median(aim[:, 0]), 2)
        figures[f"{camera}_aim_error_p95_deg"] = _round(np.percentile(aim[:, 0], 95), 2)
    for camera, pose in sorted(rec.poses.items()):
        figures[f"{camera}_pose_mean_error_px"] = _round(pose.mean_error_px, 2)
        figures[f"{camera}_pose_passpoints"] = pose.passpoints
    return figures


def _round(value: float, digits: int = 1) -> float:
    return round(float(value), digits)
