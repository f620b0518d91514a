"""Faults that come over the bus: fuzz, key churn, decode bombs, spoofed frames and poses."""

from __future__ import annotations

import os
import time

import cv2
import numpy as np

from benchmarks.faults.base import CampaignBase
from benchmarks.faults.lab import ALIVE, private_mb, wait_until
from benchmarks.faults.payloads import fuzz_payloads, jpeg_declaring, valid
from benchmarks.faults.rows import GOAL_MEMORY_MB, GOAL_POSE_REPORTED_S, Row, duration_text
from common import keys
from common import messages as m
from services.ptz.aim import aim_error_deg
from tests.calib.test_demo_calibration import MOUNTS

# Keys our meters read and that a single service writes (the secured lab lets only it):
# fuzzing them would fool the meters, not the services.
MEASURED = {keys.TRUTH_CRANE, keys.TRUTH_ROBOT, keys.GANTRY_SETPOINT, keys.GANTRY_ESTIMATE,
            keys.GANTRY_STATE, keys.HEALTH}
# Commands are fuzzed with invalid payloads only: a valid one is obeyed, which is what it is for
# (a valid collect request starts a collection); in the secured lab only the operator sends them.
COMMANDS = {keys.GANTRY_COMMAND, keys.CALIB_COLLECT, keys.PTZ_CALIBRATION, keys.PTZ_HAND}


FOLLOWING_DEG = 5.0  # a camera following the robot is aimed this well (else the row measures
# nothing: a camera held elsewhere is not aimed with any pose)


class BusFaults(CampaignBase):
    """The bus's faults, as a part of ``Campaign``."""

    def fuzz(self, per_key: int, again: bool = False) -> None:
        """Fuzz every key a service subscribes to; ``again``: twice more, for a leak."""
        topics = [t for t in vars(keys).values() if isinstance(t, keys.Topic)
                  and t not in MEASURED]
        pids, start, rounds, sent = self.pids(), time.monotonic(), [], 0
        stored = {camera: self._stored_pose(camera) for camera in MOUNTS}
        for _ in range(2 if again else 1):
            memory = self.settled_memory()
            sent = self._fuzz_once(topics, per_key)
            rounds.append((memory, self.snapshot_memory()))
        what = f"{per_key} payloads on each of {len(topics)} keys ({sent} in " \
            f"{(time.monotonic() - start) / len(rounds):.0f} s)"
        extra, ok = {}, True
        if not again:  # the fuzz is an attack on the aim too: back after it?
            aim, crane = self.recovery(time.monotonic(), self.normal_mm)
            kept = all(before is not None and (after := self._stored_pose(camera)) is not None
                       and _same_solve(before, after) for camera, before in stored.items())
            extra = {"aim ≤ 1° after": duration_text(aim), "crane back after":
                     duration_text(crane), "calib's poses": "kept" if kept else "CHANGED"}
            ok = aim is not None and crane is not None and kept
        self._survived("fuzz" + " again" * again, what, start, pids, rounds, extra, ok,
                       again=again)

    def _fuzz_once(self, topics: list[keys.Topic], per_key: int) -> int:
        sent = 0
        for topic in topics:
            params = {name: "ptz1" for name in topic.params}
            key = topic.key(self.bus.prefix, **params)
            publisher = self.session.declare_publisher(key)
            for payload in fuzz_payloads(topic, per_key, self.rng):
                if topic in COMMANDS and valid(topic, payload):
                    continue
                publisher.put(payload)
                sent += 1
                if sent % 2000 == 0:
                    time.sleep(0.01)  # the router's queues are bounded: a burst is dropped
            publisher.undeclare()
        time.sleep(2 if self.short else 3)
        for camera in MOUNTS:  # a fuzzed request may have started a collection: end it
            self.bus.publish(keys.CALIB_COLLECT, m.CollectRequest(
                measured_s=time.time(), camera=camera, action="cancel"), camera=camera)
        return sent

    def quiet(self) -> None:
        """The control: the same wait as a fault's, with no fault."""
        pids, memory, start = self.pids(), self.settled_memory(), time.monotonic()
        time.sleep(5)
        self._survived("nothing (control)", "5 s without a fault", start, pids,
                       [(memory, self.snapshot_memory())])

    def churn(self, count: int, again: bool = False) -> None:
        """Distinct keys under subscribed wildcards; ``again``: twice more, for a leak."""
        pids, start, rounds = self.pids(), time.monotonic(), []
        for _ in range(2 if again else 1):
            memory = self.settled_memory()
            self._churn_once(count)
            rounds.append((memory, self.snapshot_memory()))
        heard = self.meters.health_heard_after(time.monotonic() - 1.5)
        too_large = sum(s.dropped.get("too_large", 0) for k, s in self.bus.key_stats().items()
                        if k.startswith("stb/health/"))
        extra = {"health messages too large": too_large,
                 "services heard in the last 1.5 s": len(heard)}
        self._survived("key churn" + " again" * again, f"8 bytes on each of {count} distinct "
                       "keys", start, pids, rounds, again=again, extra=extra,
                       ok=too_large == 0 and len(heard) >= len(ALIVE))

    def _churn_once(self, count: int) -> None:
        patterns = ["stb/ptz/churn{}/state", "stb/calib/churn{}/progress",
                    "stb/health/churn/{}", "stb/sim/truth/robot/churn{}"]
        for i in range(count):
            self.session.put(patterns[i % len(patterns)].format(i), os.urandom(8))
            if i % 1000 == 999:
                time.sleep(0.01)
        time.sleep(2 if self.short else 3)

    def decode_bombs(self) -> None:
        pid = self.meters.pid("gantry")
        before, start = self.settled_memory()["gantry"], time.monotonic()
        bomb = jpeg_declaring(24000, 24000)
        for seq in range(20):
            self.bus.publish(keys.GANTRY_FRAME, m.CameraFrame(
                measured_s=time.time(), camera="tracking", seq=10**9 + seq, width_px=640,
                height_px=480, encoding="jpeg", data=bomb))
            time.sleep(0.05)
        time.sleep(2)
        after = private_mb(pid or -1)
        deaths = self.meters.deaths(start)
        held = not deaths and after - before <= GOAL_MEMORY_MB and self.meters.pid("gantry") == pid
        self.rows.append(Row("decode bombs", "no crash; the gantry's own memory ≤ +20 MB",
                             f"20 JPEGs declaring 24000×24000 in 640×480 frames: gantry "
                             f"{before:.0f} → {after:.0f} MB, restarts {len(deaths)}", held,
                             {"rss_before_mb": before, "rss_after_mb": after}))

    def spoofed_frames(self, baseline: dict) -> None:
        seconds = 3 if self.short else 8
        start = time.monotonic()
        frame = np.zeros((480, 640), np.uint8)
        cv2.circle(frame, (60, 60), 5, 255, -1)
        seq = 2 * 10**9
        while time.monotonic() - start < seconds:
            seq += 1
            self.bus.publish(keys.GANTRY_FRAME, m.CameraFrame(
                measured_s=time.time(), camera="tracking", seq=seq, width_px=640,
                height_px=480, encoding="mono8", data=frame.tobytes()))
            time.sleep(1 / 30)
        worst, aim, back, after, misses = self.crane_held(start, time.monotonic(), baseline)
        self.rows.append(Row(
            "spoofed frames", "crane stays with the robot (max gap ≤ 2× the baseline's), "
            "back ≤ 5 s after",
            f"{seq - 2 * 10**9} frames with a spot 2 m off, over {seconds} s: crane–robot max "
            f"{worst:.0f} mm (baseline max {baseline['max_mm']:.0f} mm){after}", not misses,
            {"max_gap_mm": worst, "aim_back_s": aim, "crane_back_s": back}, misses))

    def spoofed_pose(self) -> None:
        """ptz1's pose turned 40°, put on its key at the top version and one below (a pose
        at 2⁵³ once mis-aimed a camera for good): ptz1's true aim (sim truth: its head, the
        robot, its mount) must not move, calib's stored pose must not change, and calib must
        report the foreign poses."""
        mount, camera = MOUNTS["ptz1"], "ptz1"
        before = self._stored_pose(camera)
        start = time.monotonic()
        time.sleep(3)  # the aim's baseline
        spoofed_at = time.monotonic()
        for version in (2**53, 2**53 - 1):
            self.bus.publish(keys.CALIB_POSE, m.CameraPose(
                measured_s=time.time(), camera=camera,
                **(mount.fields() | {"rz_deg": mount.rz_deg + 40.0}), focal_px=743.1,
                mean_error_px=0.5, passpoints=100, version=version), camera=camera)

        def reported() -> float | None:
            with self.meters.lock:
                entry = self.meters.health.get("calib/main")
            if entry is None or entry[0] <= spoofed_at or "did not send" not in entry[1].detail:
                return None
            return entry[0] - spoofed_at

        wait_until(lambda: reported() is not None, timeout=8)
        r = reported()  # the first health that says so (a later one replaces it)
        time.sleep(max(0.0, spoofed_at + 5 - time.monotonic()))  # the PTZ service asked again
        stored_after = self._stored_pose(camera)
        aim_before = self._worst_aim_deg(camera, start, spoofed_at)
        aim_after = self._worst_aim_deg(camera, spoofed_at)
        kept = before is not None and stored_after is not None and \
            _same_solve(before, stored_after)
        bound = aim_before + 2.0
        misses = ([] if aim_before <= FOLLOWING_DEG else ["ptz1 did not follow the robot before"])
        misses += [] if aim_after <= bound else ["aimed with"]
        misses += [] if kept else ["calib's pose changed"]
        misses += [] if r is not None and r <= GOAL_POSE_REPORTED_S else ["not reported"]
        aim, back = self.recovery(spoofed_at, self.normal_mm)
        after, not_back = self._back_text(aim, back)
        misses += not_back
        self.rows.append(Row(
            "spoofed pose", "not aimed with (true aim ≤ baseline + 2°, baseline ≤ 5°), calib's "
            "pose kept, reported ≤ 5 s",
            f"ptz1 turned 40° at version 2⁵³ and 2⁵³−1: ptz1's true aim error at most "
            f"{aim_after:.1f}° over the next 5 s ({aim_before:.1f}° before); calib's pose "
            f"{'unchanged' if kept else 'CHANGED'}; calib health degraded after "
            f"{duration_text(r)}{after}", not misses,
            {"aim_before_deg": aim_before, "aim_after_deg": aim_after, "reported_s": r,
             "aim_back_s": aim},
            misses))

    def _stored_pose(self, camera: str) -> m.CameraPose | None:
        answers = [p for p in self.bus.query_latest(keys.CALIB_POSE, camera=camera)
                   if p.camera == camera]
        return answers[0] if answers else None

    def _worst_aim_deg(self, camera: str, start: float, end: float | None = None) -> float:
        """The largest angle between where ``camera`` truly looks and the true robot."""
        seen = self.meters.ptz_window(camera, start, end)
        return max((aim_error_deg(np.array([robot.x_mm, robot.y_mm, robot.z_mm]),
                                  MOUNTS[camera], head.pan_deg, head.tilt_deg)
                    for head, robot in seen), default=float("nan"))


def _same_solve(a: m.CameraPose, b: m.CameraPose) -> bool:
    return a.model_dump(exclude={"sent_s"}) == b.model_dump(exclude={"sent_s"})
