"""Calib service: keeps every camera's pose, and collects passpoints to find it (paper §2.2).

Publishes:  stb/calib/{camera}/pose (CameraPose) at start for every stored pose and after each
            solve, as news; and answers queries on it with its stored pose — the only pose a
            PTZ service takes (it asks this queryable whenever a pose is heard, not the message)
            stb/calib/{camera}/progress (CollectProgress) while collecting
            A pose on its key that it did not send (a stale or poisoned one) changes nothing
            here: it is counted, and its health says so for a minute
Subscribes: stb/calib/{camera}/collect (CollectRequest: start or cancel a collection, accept
            or discard a solved pose held for review)
            stb/calib/{camera}/pose (to hear poses it did not send)
            while collecting: stb/tracker/markers, stb/ptz/{camera}/detections, .../snapshot,
            .../state; puts stb/ptz/{camera}/calibration (the camera's calibration mode)
Stores:     <data_dir>/<camera>/ pose.json, passpoints.csv, track.csv, images/
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from functools import partial

from common import keys
from common import messages as m
from common.node import Node
from services.calib.pose_rules import (
    ForeignPoses,
    health,
    next_version,
    rotation_gap_deg,
    same_solve,
)
from services.calib.session import Session
from services.calib.settings import CalibSettings
from services.calib.store import PoseStore

OfACamera = m.MarkerDetections | m.CameraFrame | m.PtzState  # what a session is told

log = logging.getLogger(__name__)


class Calib:
    def __init__(self, node: Node, settings: CalibSettings, store: PoseStore) -> None:
        self.node, self.settings, self.store = node, settings, store
        self.lock = threading.Lock()
        self.poses: dict[str, m.CameraPose] = {}
        self.sessions: dict[str, Session] = {}
        self.foreign = ForeignPoses()  # when poses it did not send were heard (monotonic)
        self.status_due: threading.Timer | None = None  # the status once the minute is over

    def start(self) -> None:
        bus = self.node.bus
        for camera in self.settings.cameras:
            pose = self.store.load(camera)
            if pose is not None:
                self.poses[camera] = pose
                log.info("%s: stored pose (%.2f px over %d passpoints)", camera,
                         pose.mean_error_px, pose.passpoints)
                bus.publish(keys.CALIB_POSE, pose, camera=camera)
            bus.serve_latest(keys.CALIB_POSE, partial(self.poses.get, camera), camera=camera)
            bus.subscribe(keys.CALIB_POSE, self.on_pose_heard, latest=False, camera=camera)
            bus.subscribe(keys.CALIB_COLLECT, self.on_request, latest=False, camera=camera)
        bus.subscribe(keys.TRACKER_MARKERS, self._each_session("on_frame"), latest=False)
        bus.subscribe(keys.PTZ_DETECTIONS, self._to_session("on_detections"), latest=False)
        bus.subscribe(keys.PTZ_SNAPSHOT, self._to_session("on_snapshot"), latest=False,
                      queue_size=50)
        bus.subscribe(keys.PTZ_STATE, self._to_session("on_state"), latest=False)
        if self.settings.collect_missing:
            for camera in self.settings.cameras:
                if camera not in self.poses:
                    log.info("%s: no stored pose; collecting passpoints", camera)
                    self._start(camera, self.settings.count, self.settings.timeout_s)
        self._report_status()

    def on_request(self, msg: m.CollectRequest) -> None:
        if msg.camera not in self.settings.cameras:
            log.warning("collect request for unknown camera %s (known: %s)", msg.camera,
                        ", ".join(self.settings.cameras))
            return
        with self.lock:
            session = self.sessions.get(msg.camera)
        if msg.action == "cancel":
            if session is not None:
                session.cancel()
            return
        if msg.action in ("accept", "discard"):
            if session is None or not session.decide(accept=msg.action == "accept"):
                log.warning("%s: %s, but no solved pose waits for review", msg.camera,
                            msg.action)
            return
        if session is not None and session.running:
            log.info("%s: a collection is already running", msg.camera)
            session.publish_progress()
            return
        self._start(msg.camera, msg.count, msg.timeout_s, msg.review, msg.zooms,
                    msg.step_count)

    def solved(self, pose: m.CameraPose, report: dict) -> None:
        with self.lock:
            pose = next_version(pose, self.poses.get(pose.camera))
            self.poses[pose.camera] = pose
        self.store.save(pose, report)
        self.node.bus.publish(keys.CALIB_POSE, pose, camera=pose.camera)
        self._report_status()

    def on_pose_heard(self, msg: m.CameraPose) -> None:
        """Its own echo, or a pose it did not send: counted and reported, nothing else — the
        stored pose is the truth, and PTZ services ask for it."""
        camera = msg.camera
        with self.lock:
            own = self.poses.get(camera)
            if own is not None and same_solve(msg, own):
                return
            first = self.foreign.heard(camera, time.monotonic())
        if first:
            log.warning("%s: a pose it did not send (version %d%s) on the bus; PTZ services "
                        "take only the stored one, asked of this service", camera, msg.version,
                        "" if own is None else
                        f", up to {rotation_gap_deg(msg, own):.1f}° from its own")
        self._report_status()

    def _start(self, camera: str, count: int, timeout_s: float, review: bool = False,
               zooms: list[int] | None = None, step_count: int | None = None) -> None:
        session = Session(self.node, self.settings, self.store, camera, count, timeout_s,
                          on_pose=self.solved, review=review, zooms=zooms or [],
                          step_count=step_count)
        with self.lock:
            self.sessions[camera] = session
        threading.Thread(target=session.run, name=f"collect-{camera}", daemon=True).start()

    def _each_session(self, method: str) -> Callable[[m.Message], None]:
        def handler(msg: m.Message) -> None:
            with self.lock:
                sessions = [s for s in self.sessions.values() if s.running]
            for session in sessions:
                getattr(session, method)(msg)
        return handler

    def _to_session(self, method: str) -> Callable[[OfACamera], None]:
        def handler(msg: OfACamera) -> None:
            with self.lock:
                session = self.sessions.get(msg.camera)
            if session is not None and session.running:
                getattr(session, method)(msg)
        return handler

    def _report_status(self) -> None:
        now = time.monotonic()
        with self.lock:
            status = health(self.settings.cameras, self.poses, self.foreign.counts(now))
            change_s = self.foreign.next_change_s()
        self.node.set_status(*status)
        with self.lock:  # and again when a foreign pose leaves the window
            due = self.status_due
            pending = due is not None and due.is_alive() and due is not threading.current_thread()
            if change_s is not None and not pending:
                self.status_due = threading.Timer(change_s - now + 0.5, self._report_status)
                self.status_due.daemon = True
                self.status_due.start()


def run(node: Node[CalibSettings]) -> None:
    settings = node.settings
    Calib(node, settings, PoseStore(settings.data_dir)).start()
    node.stop.wait()
