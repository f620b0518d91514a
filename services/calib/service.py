"""Calib service: keeps every camera's pose, and collects passpoints to find it (paper §2.2).

Publishes:  stb/calib/{camera}/pose (CameraPose) at start for every stored pose and after each
            solve; answers queries on it for late joiners
            stb/calib/{camera}/progress (CollectProgress) while collecting
Subscribes: stb/calib/{camera}/collect (CollectRequest: start or cancel a collection)
            while collecting: stb/tracker/markers, stb/ptz/{camera}/detections, .../snapshot,
            .../state; puts stb/ptz/{camera}/calibration (the camera's calibration mode)
Stores:     <data_dir>/<camera>/ pose.json, passpoints.csv, track.csv, images/
"""

from __future__ import annotations

import logging
import threading

from common import keys
from common import messages as m
from common.node import Node
from services.calib.session import Session
from services.calib.settings import CalibSettings
from services.calib.store import PoseStore

log = logging.getLogger(__name__)


class Calib:
    def __init__(self, node: Node, settings: CalibSettings, store: PoseStore) -> None:
        self.node, self.settings, self.store = node, settings, store
        self.lock = threading.Lock()
        self.poses: dict[str, m.CameraPose] = {}
        self.sessions: dict[str, Session] = {}

    def start(self) -> None:
        bus = self.node.bus
        for camera in self.settings.cameras:
            pose = self.store.load(camera)
            if pose is not None:
                self.poses[camera] = pose
                log.info("%s: stored pose (%.2f px over %d passpoints)", camera,
                         pose.mean_error_px, pose.passpoints)
                bus.publish(keys.CALIB_POSE, pose, camera=camera)
            bus.serve_latest(keys.CALIB_POSE, lambda c=camera: self.poses.get(c), camera=camera)
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
        if session is not None and session.running:
            log.info("%s: a collection is already running", msg.camera)
            session.publish_progress()
            return
        self._start(msg.camera, msg.count, msg.timeout_s)

    def solved(self, pose: m.CameraPose) -> None:
        with self.lock:
            self.poses[pose.camera] = pose
        self.node.bus.publish(keys.CALIB_POSE, pose, camera=pose.camera)
        self._report_status()

    def _start(self, camera: str, count: int, timeout_s: float) -> None:
        session = Session(self.node, self.settings, self.store, camera, count, timeout_s,
                          on_pose=self.solved)
        with self.lock:
            self.sessions[camera] = session
        threading.Thread(target=session.run, name=f"collect-{camera}", daemon=True).start()

    def _each_session(self, method: str):  # type: ignore[no-untyped-def]
        def handler(msg: m.Message) -> None:
            with self.lock:
                sessions = [s for s in self.sessions.values() if s.running]
            for session in sessions:
                getattr(session, method)(msg)
        return handler

    def _to_session(self, method: str):  # type: ignore[no-untyped-def]
        def handler(msg: m.Message) -> None:
            with self.lock:
                session = self.sessions.get(msg.camera)  # type: ignore[attr-defined]
            if session is not None and session.running:
                getattr(session, method)(msg)
        return handler

    def _report_status(self) -> None:
        missing = [c for c in self.settings.cameras if c not in self.poses]
        self.node.set_status("degraded" if missing else "ok",
                             f"no pose yet: {', '.join(missing)}" if missing else "")


def run(node: Node) -> None:
    settings: CalibSettings = node.settings  # type: ignore[assignment]
    Calib(node, settings, PoseStore(settings.data_dir)).start()
    node.stop.wait()
