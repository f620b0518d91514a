"""Tracker service: every mocap frame's markers, and the robot marker's position and velocity.

Reads:      Qualisys QTM over the RT protocol (qtm_host:qtm_port)
Publishes:  stb/tracker/markers (MarkerFrame), every frame
            stb/tracker/robot   (RobotPosition), every frame in which the robot is seen: its
                                marker, or with ``robot_body`` its 6DOF body (origin and
                                orientation; a frame in which QTM lost the body has none)
A frame captured longer than ``bus.max_age_s`` ago (a backlog after a stall) gives no robot
sample (counted as stale on stb/tracker/robot in the service's health); its markers still go
out, stamped with their capture time, for calibration and recordings.
"""

from __future__ import annotations

from common import keys
from common import messages as m
from common.node import Node
from common.robot_picker import RobotPicker, Seen
from services.tracker.mocap import MotionCapture, QualisysMocap
from services.tracker.settings import TrackerSettings


def make_mocap(settings: TrackerSettings) -> QualisysMocap:
    return QualisysMocap(settings.qtm_host, settings.qtm_port, frames=settings.frames,
                         body=settings.robot_body)


def make_picker(settings: TrackerSettings) -> RobotPicker:
    return RobotPicker(settings.robot_body or settings.robot_label, settings.volume,
                       min_motion_mm=settings.min_motion_mm,
                       velocity_window_s=settings.velocity_window_s)


def run(node: Node[TrackerSettings], mocap: MotionCapture | None = None) -> None:
    settings = node.settings
    mocap = mocap or make_mocap(settings)
    picker = make_picker(settings)

    def on_frame(frame: m.MarkerFrame) -> None:
        body = next((b for b in frame.bodies if b.name == settings.robot_body), None) \
            if settings.robot_body else None
        if settings.robot_body:
            seen = [] if body is None else [Seen(body.name, 0, body.x_mm, body.y_mm, body.z_mm)]
            robot = picker.update(frame.measured_s, seen)
        else:
            robot = picker.update(frame.measured_s, frame.markers)
        if robot is not None:  # first: the robot sample is what the cameras wait for
            # a frame from a backlog (the tracker stalled) gives no robot sample: it is
            # control input, never sent as fresh (the bus judges its age at the sent stamp);
            # the frame itself goes on below with its true capture time
            (x, y, z), (vx, vy, vz) = robot
            node.bus.publish(keys.TRACKER_ROBOT, m.RobotPosition(
                measured_s=frame.measured_s, label="" if body else settings.robot_label,
                x_mm=x, y_mm=y, z_mm=z, vx_mm_s=vx, vy_mm_s=vy, vz_mm_s=vz,
                body=body.name if body else "", qw=body.qw if body else None,
                qx=body.qx if body else None, qy=body.qy if body else None,
                qz=body.qz if body else None),
                max_age_s=settings.bus.max_age_s)
        node.bus.publish(keys.TRACKER_MARKERS, frame)

    def on_state(connected: bool, why: str) -> None:
        node.set_status("ok" if connected else "degraded", "" if connected else why)

    mocap.run(on_frame, node.stop, on_state)
