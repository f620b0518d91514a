"""What the operator's page shows, as a pure function of what arrived on the bus (no I/O, no
clock of its own): ``LiveState.view(now)`` is the JSON the page draws from."""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from common import messages as m
from common.camera import Pose, head_pose
from services.web.alarms import AlarmBoard, calibration_alarms, crane_alarms, service_alarms

TRACK_MIN_STEP_S = 0.1
HISTORY_STEP_S = 1.0  # the plot's resolution: the largest error and pull of each second
# A lab has a handful of cameras, robots and services; names beyond these many (a key churn)
# push out the longest unheard, so that memory stays flat whatever arrives.
MAX_CAMERAS, MAX_ROBOTS, MAX_SERVICES = 16, 8, 64
MAX_COMMANDS = 20  # the page's command history: the latest operators' commands and answers
GROUND_Z_MM = 0.0
LOOK_MAX_MM = 8000.0


def looking_at(pose: m.CameraPose, pan_deg: float, tilt_deg: float) -> list[float] | None:
    """Where a camera's optical axis meets the ground (x, y), or a point ``LOOK_MAX_MM`` along
    it when it looks up or far away; None without a usable pose."""
    head = head_pose(Pose.of(pose), pan_deg, tilt_deg)
    axis = head.rotation @ np.array([1.0, 0.0, 0.0])
    origin = head.position
    reach = LOOK_MAX_MM
    if axis[2] < -1e-6:
        reach = min(reach, (GROUND_Z_MM - origin[2]) / axis[2])
    point = origin + axis * reach
    if not np.all(np.isfinite(point)):
        return None
    return [round(float(point[0]), 1), round(float(point[1]), 1)]


def _keep(latest: dict, key: Any, value: Any, limit: int) -> None:
    """``latest[key] = value``, the most recently heard last; beyond ``limit`` keys the
    longest unheard goes."""
    latest.pop(key, None)
    latest[key] = value
    while len(latest) > limit:
        del latest[next(iter(latest))]


@dataclass
class LiveState:
    """The latest of everything the page shows; ``track_s`` of robot track and ``history_s``
    of crane error and sideways pull are kept."""

    track_s: float = 60.0
    history_s: float = 300.0
    alive: set[tuple[str, str]] = field(default_factory=set)
    seen: dict[tuple[str, str], None] = field(default_factory=dict)  # listed when it goes
    health: dict[tuple[str, str], m.ServiceHealth] = field(default_factory=dict)
    robot: m.RobotPosition | None = None
    truth: dict[str, m.RobotTruth] = field(default_factory=dict)
    track: deque[tuple[float, float, float]] = field(default_factory=deque)
    crane: m.CraneState | None = None
    estimate: m.RobotEstimate | None = None
    offload: m.GravityOffload | None = None
    ptz: dict[str, m.PtzState] = field(default_factory=dict)
    poses: dict[str, m.CameraPose] = field(default_factory=dict)
    previews: dict[str, m.PtzPreview] = field(default_factory=dict)
    videos: dict[str, m.CameraFrame] = field(default_factory=dict)  # stb/video/<camera>
    # calibration mode: the latest snapshot and the markers found in it (same capture time)
    snapshots: dict[str, tuple[m.CameraFrame, list[m.DetectedMarker]]] = field(
        default_factory=dict)
    detections: dict[str, m.MarkerDetections] = field(default_factory=dict)
    collections: dict[str, m.CollectProgress] = field(default_factory=dict)
    collecting_since: dict[str, float] = field(default_factory=dict)
    history: deque[list[float]] = field(default_factory=deque)  # [t, error mm, pull %]
    alarms: AlarmBoard = field(default_factory=AlarmBoard)
    commands: dict[str, dict[str, Any]] = field(default_factory=dict)  # by id, oldest first

    def on_alive(self, service: str, instance: str, alive: bool) -> None:
        (self.alive.add if alive else self.alive.discard)((service, instance))
        _keep(self.seen, (service, instance), None, MAX_SERVICES)
        self.alive &= self.seen.keys()

    def on_message(self, msg: m.Message) -> None:  # noqa: C901 - one branch per message kind
        if isinstance(msg, m.RobotPosition):
            self.robot = msg
            if not self.track or msg.measured_s - self.track[-1][0] >= TRACK_MIN_STEP_S:
                self.track.append((msg.measured_s, msg.x_mm, msg.y_mm))
            while self.track and msg.measured_s - self.track[0][0] > self.track_s:
                self.track.popleft()
        elif isinstance(msg, m.CraneState):
            self.crane = msg
        elif isinstance(msg, m.RobotEstimate):
            self.estimate = msg
        elif isinstance(msg, m.GravityOffload):
            self.offload = msg
            self._remember(msg)
        elif isinstance(msg, m.PtzState):
            _keep(self.ptz, msg.camera, msg, MAX_CAMERAS)
        elif isinstance(msg, m.CameraPose):
            old = self.poses.get(msg.camera)
            if old is None or msg.measured_s >= old.measured_s:
                _keep(self.poses, msg.camera, msg, MAX_CAMERAS)
        elif isinstance(msg, m.PtzPreview):
            _keep(self.previews, msg.camera, msg, MAX_CAMERAS)
        elif isinstance(msg, m.CameraFrame) and msg.encoding == "jpeg":
            found = self.detections.get(msg.camera)  # each key has its thread: either first
            markers = found.markers if found and found.measured_s == msg.measured_s else []
            _keep(self.snapshots, msg.camera, (msg, markers), MAX_CAMERAS)
        elif isinstance(msg, m.MarkerDetections):
            _keep(self.detections, msg.camera, msg, MAX_CAMERAS)
            shot = self.snapshots.get(msg.camera)
            if shot is not None and shot[0].measured_s == msg.measured_s:
                self.snapshots[msg.camera] = (shot[0], msg.markers)
        elif isinstance(msg, m.CollectProgress):
            previous = self.collections.get(msg.camera)
            if previous is None or previous.state not in ("collecting", "solving"):
                _keep(self.collecting_since, msg.camera, msg.measured_s, MAX_CAMERAS)
            _keep(self.collections, msg.camera, msg, MAX_CAMERAS)
        elif isinstance(msg, m.ServiceHealth):
            _keep(self.health, (msg.service, msg.instance), msg, MAX_SERVICES)
        elif isinstance(msg, m.RobotTruth):
            _keep(self.truth, msg.robot, msg, MAX_ROBOTS)
        elif isinstance(msg, m.GantryCommand | m.GantryCommandReply):
            self._command(msg)

    def on_video(self, frame: m.CameraFrame) -> None:
        """A camera's video frame (the observation camera's bird's-eye view)."""
        if frame.encoding == "jpeg":
            _keep(self.videos, frame.camera, frame, MAX_CAMERAS)

    def video_jpeg(self, camera: str) -> bytes | None:
        frame = self.videos.get(camera)
        return None if frame is None else frame.data

    def _remember(self, offload: m.GravityOffload) -> None:
        """The plot's history: per ``HISTORY_STEP_S``, the largest error and pull."""
        t = math.floor(offload.measured_s / HISTORY_STEP_S) * HISTORY_STEP_S
        point = [t, offload.horizontal_error_mm, offload.horizontal_share_pct]
        if self.history and self.history[-1][0] == t:
            last = self.history[-1]
            last[1], last[2] = max(last[1], point[1]), max(last[2], point[2])
        elif not self.history or t > self.history[-1][0]:
            self.history.append(point)
        while self.history and self.history[0][0] < t - self.history_s:
            self.history.popleft()

    def judge(self, now_s: float, services: list[dict[str, Any]] | None = None) -> None:
        """Alarms begin and end by what is known at ``now_s`` (the service calls this on a
        timer, so that an alarm's start does not wait for a page to look); ``services``: the
        rows of ``_services(now_s)`` when the caller has them."""
        rows = self._services(now_s) if services is None else services
        self.alarms.update(
            crane_alarms(self.crane, self.estimate, self.offload, now_s)
            + service_alarms(rows) + calibration_alarms(self.collections), now_s)

    def _command(self, msg: m.GantryCommand | m.GantryCommandReply) -> None:
        """A command or its answer (either may come first: each key has its thread)."""
        entry = self.commands.get(msg.id) or {"at_s": msg.measured_s, "command": msg.command,
                                              "by": "", "reason": "", "accepted": None,
                                              "detail": ""}
        if isinstance(msg, m.GantryCommand):
            entry.update(at_s=msg.measured_s, by=msg.operator, reason=msg.reason)
        else:
            entry.update(accepted=msg.accepted, detail=msg.detail)
        self.commands[msg.id] = entry
        while len(self.commands) > MAX_COMMANDS:
            del self.commands[next(iter(self.commands))]

    def view(self, now_s: float) -> dict[str, Any]:
        """Everything the page draws, JSON-ready (images only by sequence number)."""
        services = self._services(now_s)
        self.judge(now_s, services)
        return {
            "now_s": now_s,
            "alarms": self.alarms.view(),
            "history": {"step_s": HISTORY_STEP_S, "span_s": self.history_s,
                        "limit_pct": None if self.offload is None
                        else self.offload.warn_above_pct,
                        "points": [[round(t - now_s, 1), round(e), round(p, 2)]
                                   for t, e, p in self.history]},
            "services": services,
            "videos": {name: {"seq": f.seq, "width_px": f.width_px, "height_px": f.height_px,
                              "age_s": now_s - f.measured_s} for name, f in self.videos.items()},
            "robot": None if self.robot is None else {
                "x_mm": self.robot.x_mm, "y_mm": self.robot.y_mm, "z_mm": self.robot.z_mm,
                "speed_mm_s": math.hypot(self.robot.vx_mm_s, self.robot.vy_mm_s),
                "age_s": now_s - self.robot.measured_s},
            "track": [[round(x, 1), round(y, 1)] for _, x, y in self.track],
            "truth": {name: [t.x_mm, t.y_mm] for name, t in self.truth.items()},
            "crane": None if self.crane is None else {
                "x_mm": self.crane.x_mm, "y_mm": self.crane.y_mm, "status": self.crane.status,
                "target_x_mm": self.crane.target_x_mm, "target_y_mm": self.crane.target_y_mm,
                "enabled": self.crane.enabled, "age_s": now_s - self.crane.measured_s,
                "mode": self.crane.mode, "mode_by": self.crane.mode_by,
                "mode_reason": self.crane.mode_reason, "safety_ok": self.crane.safety_ok},
            "estimate": None if self.estimate is None else {
                "x_mm": self.estimate.x_mm, "y_mm": self.estimate.y_mm,
                "valid": self.estimate.valid, "algorithm": self.estimate.algorithm},
            "offload": None if self.offload is None else {
                "horizontal_error_mm": self.offload.horizontal_error_mm,
                "cable_length_mm": self.offload.cable_length_mm,
                "vertical_loss_pct": self.offload.vertical_loss_pct,
                "horizontal_share_pct": self.offload.horizontal_share_pct,
                "warn_above_pct": self.offload.warn_above_pct,
                "warning": self.offload.warning},
            "cameras": self._cameras(),
            "commands": [dict(c) for c in sorted(self.commands.values(),
                                                 key=lambda c: -c["at_s"])],
        }

    def _services(self, now_s: float) -> list[dict[str, Any]]:
        names = sorted(set(self.seen) | set(self.health))
        out = []
        for service, instance in names:
            health = self.health.get((service, instance))
            out.append({"service": service, "instance": instance,
                        "alive": (service, instance) in self.alive,
                        "status": health.status if health else "",
                        "detail": health.detail if health else "",
                        "health_age_s": None if health is None else now_s - health.measured_s})
        return out

    def _cameras(self) -> dict[str, dict[str, Any]]:
        out: dict[str, dict[str, Any]] = {}
        for camera in sorted(set(self.ptz) | set(self.poses) | set(self.previews)
                             | set(self.snapshots)
                             | set(self.collections)):
            state, pose, preview = (self.ptz.get(camera), self.poses.get(camera),
                                    self.previews.get(camera))
            entry: dict[str, Any] = {"status": state.status if state else "",
                                     "pan_deg": state.pan_deg if state else None,
                                     "tilt_deg": state.tilt_deg if state else None,
                                     "zoom": state.zoom if state else None,
                                     "held_by": state.held_by if state else "",
                                     "presets": list(state.presets) if state else [],
                                     "aim_error_deg": state.aim_error_deg if state else None,
                                     "pointing_error_deg":
                                         state.pointing_error_deg if state else None,
                                     "pointing_problem": state.pointing_problem if state else "",
                                     "position": None, "looking_at": None, "preview": None,
                                     "calibration": _collection(
                                         self.collections.get(camera),
                                         self.collecting_since.get(camera))}
            if pose is not None:
                entry["position"] = [pose.x_mm, pose.y_mm, pose.z_mm]
                entry["pose_error_px"] = pose.mean_error_px
                if state is not None and state.status != "camera_unreachable":
                    entry["looking_at"] = looking_at(pose, state.pan_deg, state.tilt_deg)
            shot = self.snapshots.get(camera)
            if shot is not None and (preview is None
                                     or shot[0].measured_s > preview.measured_s):
                frame, markers = shot
                entry["preview"] = {
                    "seq": f"snapshot-{frame.seq}", "kind": "calibration snapshot",
                    "width_px": frame.width_px, "height_px": frame.height_px,
                    "robot_px": None, "markers": _drawn(markers),
                    "measured_s": frame.measured_s}
            elif preview is not None:
                entry["preview"] = {
                    "seq": f"preview-{preview.seq}", "kind": "preview",
                    "width_px": preview.width_px, "height_px": preview.height_px,
                    "robot_px": preview.robot_px, "markers": _drawn(preview.markers),
                    "measured_s": preview.measured_s}
            out[camera] = entry
        return out

    def preview_jpeg(self, camera: str) -> bytes | None:
        """The camera's latest picture: its preview, or in calibration mode its snapshot."""
        preview, shot = self.previews.get(camera), self.snapshots.get(camera)
        if shot is not None and (preview is None or shot[0].measured_s > preview.measured_s):
            return shot[0].data
        return None if preview is None else preview.jpeg


def _drawn(markers: list[m.DetectedMarker]) -> list[list[float]]:
    return [[d.u_px, d.v_px, d.radius_long_px] for d in markers]


def _collection(progress: m.CollectProgress | None, since_s: float | None
                ) -> dict[str, Any] | None:
    """The camera's latest passpoint collection, as the page shows it: how far, what was
    passed over, and the time left at the pace so far."""
    if progress is None:
        return None
    left = None
    if progress.state == "collecting" and progress.passpoints > 0 and since_s is not None:
        pace = (progress.measured_s - since_s) / progress.passpoints
        left = round(max(0, progress.target - progress.passpoints) * pace, 1)
    return {"state": progress.state, "passpoints": progress.passpoints,
            "target": progress.target, "message": progress.message,
            "snapshots": progress.snapshots, "skipped": dict(progress.skipped),
            "time_left_s": left, "mean_error_px": progress.mean_error_px}
