"""Faults that try to steer the lab with messages and files that look right: frames with a
drifting spot, floods of calibration requests and of commands, a foreign web page at
``stb foxglove``, the crater file rewritten while read. After each, the sim's truth says
whether every camera aims at the robot again (≤ 1° within 10 s) and the crane is back
with it (within the baseline's largest gap within 5 s)."""

from __future__ import annotations

import asyncio
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import websockets

from benchmarks.faults.base import CampaignBase
from benchmarks.faults.lab import ALIVE, ROOT, interrupt, wait_until
from benchmarks.faults.rows import Row, duration_text
from common import keys
from common import messages as m
from common.heightmap import HeightMap
from services.recording.origin_gate import SUBPROTOCOLS
from tests.calib.test_demo_calibration import MOUNTS
from tests.conftest import free_port
from tests.uplab import VIEWER
from tests.webpage import PageClient

DRIFT_PX_S = 15.0  # the spoofed spot's drift: slow enough to pass a gate frame by frame
FLOOD = 3000


class TrustFaults(CampaignBase):
    """As a part of ``Campaign``."""

    # --- the faults ---------------------------------------------------------------------

    def drifting_frames(self, baseline: dict) -> None:
        """Each real tracking frame sent again with the picture moved sideways, more each
        second: the spot drifts slowly, so that each frame alone is near the one before."""
        seconds = 5 if self.short else 10
        start, sent = time.monotonic(), [0]

        def resend(frame: m.CameraFrame) -> None:
            if (frame.seq >= 10**9 or frame.encoding != "mono8"
                    or time.monotonic() > start + seconds):
                return
            image = np.frombuffer(frame.data, np.uint8).reshape(frame.height_px, frame.width_px)
            shift = int(DRIFT_PX_S * (time.monotonic() - start))
            moved = np.roll(image, shift, axis=1)
            self.bus.publish(keys.GANTRY_FRAME, frame.model_copy(update={
                "seq": frame.seq + 3 * 10**9, "data": moved.tobytes()}))
            sent[0] += 1

        subscription = self.bus.subscribe(keys.GANTRY_FRAME, resend, latest=False)
        wait_until(lambda: time.monotonic() > start + seconds, seconds + 5, 0.2)
        end = time.monotonic()
        subscription.close()
        worst, aim, back, after, misses = self.crane_held(start, end, baseline)
        self.rows.append(Row(
            "drifting spoofed frames", "crane stays with the robot (max gap ≤ 2× the "
            "baseline's), back ≤ 5 s after",
            f"{sent[0]} real frames sent again with the spot drifting {DRIFT_PX_S:g} px/s "
            f"for {seconds} s: crane–robot max {worst:.0f} mm (baseline max "
            f"{baseline['max_mm']:.0f} mm){after}", not misses,
            {"max_gap_mm": worst, "aim_back_s": aim, "crane_back_s": back}, misses))

    def calibration_flood(self, baseline: dict) -> None:
        """3,000 valid calibration-mode requests at each camera in about 3.5 s: on and off,
        random holds, short leases (a collector's requests, from anyone on the open bus)."""
        rng = np.random.default_rng(3)
        start_wall, start = time.time(), time.monotonic()
        for i in range(FLOOD):
            for camera in MOUNTS:
                self.bus.publish(keys.PTZ_CALIBRATION, m.CalibrationMode(
                    measured_s=time.time(), camera=camera, active=bool(i % 7),
                    pan_deg=float(rng.uniform(-180, 180)), tilt_deg=float(rng.uniform(-90, 0)),
                    zoom=int(rng.integers(1, 9999)), lease_s=0.5), camera=camera)
            if i % 100 == 99:
                time.sleep(0.11)  # about 3.5 s in all, as the campaign that found it
        end = time.monotonic()
        seconds = end - start
        wait_until(lambda: time.monotonic() > end + 1.0, 5, 0.1)  # the last leases ran out
        aim, back = self.recovery(end + 0.5, baseline["max_mm"])
        manual = sorted({s.camera for s in self.meters.ptz_states
                         if s.measured_s >= start_wall and s.status == "manual"})
        after, misses = self._back_text(aim, back)
        misses = (["manual: " + ", ".join(manual)] if manual else []) + misses
        self.rows.append(Row(
            "calibration-mode flood", "no camera taken for someone else's (manual); every "
            "camera's true aim ≤ 1° ≤ 10 s after",
            f"{FLOOD} requests at each of {len(MOUNTS)} cameras in {seconds:.1f} s: cameras "
            f"declared manual: {', '.join(manual) or 'none'}{after}", not misses,
            {"aim_back_s": aim, "crane_back_s": back, "manual": manual}, misses))

    def command_flood(self, baseline: dict) -> None:
        """3,000 disarms from one bus identity under 1,000 names as fast as the bus takes them:
        the gantry carries out a few a second at most and answers the rest "too many" for that
        identity; the operator's arm right after is taken, and the crane is back with the
        robot."""
        start = time.monotonic()
        for i in range(FLOOD):
            self.bus.publish(keys.GANTRY_COMMAND, m.GantryCommand(
                measured_s=time.time(), command="disarm", operator=f"name {i % 1000}",
                reason="flood", id=f"flood-{i}"), sender="intruder")
        end = time.monotonic()
        seconds = end - start
        armed_at = None  # the operator arms again at once, as often as an operator would
        while armed_at is None and time.monotonic() < end + 10:
            reply = self.operator("arm")
            if reply is not None and reply.accepted:
                armed_at = time.monotonic()
            else:
                time.sleep(0.5)

        def answered() -> list[m.GantryCommandReply]:
            return [r for r in self.meters.replies if r.id.startswith("flood-")]

        counts: list[int] = []  # every reply is in once their count stops growing

        def stopped_growing() -> bool:
            counts.append(len(answered()))
            return counts[-5:] == [counts[-1]] * 5
        wait_until(stopped_growing, 10, 0.2)
        answers = answered()
        obeyed = [r for r in answers if "too many" not in r.detail]
        bound = self.gantry.command_burst + self.gantry.command_per_s * (seconds + 1.0)
        aim, back = self.recovery(armed_at or time.monotonic(), baseline["max_mm"])
        crane = self.meters.crane_window(start)  # from the flood until the crane is back
        worst = float(crane[:, 3].max()) if len(crane) else float("nan")
        refused = [r for r in self.meters.replies
                   if r.id.startswith("campaign-") and "too many" in r.detail]
        after, misses = self._back_text(aim, back)
        misses = ([] if len(obeyed) <= bound else ["obeyed"]) + \
            ([] if armed_at is not None and not refused else ["operator refused"]) + misses
        # the crane's largest gap is a figure, not a goal: the burst's disarms are carried
        # out (anyone allowed to command may disarm), the crane disabled until the operator
        # arms again (docs/reliability.md)
        self.rows.append(Row(
            "command flood", f"≤ {self.gantry.command_burst} + {self.gantry.command_per_s:g}/s "
            "carried out, the rest \"too many\"; the operator never refused; crane back ≤ 5 s",
            f"{FLOOD} disarms under 1000 names from one identity in {seconds:.1f} s: "
            f"{len(answers)} answered, "
            f"{len(obeyed)} carried out (bound {bound:.0f}); the operator's arm taken "
            f"{duration_text(None if armed_at is None else armed_at - end)} after the flood, "
            f"its commands refused as too many: {len(refused)}; crane–robot max {worst:.0f} mm "
            f"(baseline max {baseline['max_mm']:.0f} mm){after}", not misses,
            {"answered": len(answers), "obeyed": len(obeyed), "aim_back_s": aim,
             "crane_back_s": back, "worst_mm": worst, "operator_refused": len(refused)},
            misses))

    def foreign_origin(self) -> None:
        """``stb foxglove`` against the lab, and a web page from elsewhere that opens a
        WebSocket to it (as any page in an operator's browser can)."""
        port = free_port()
        proc = subprocess.Popen(
            [sys.executable, "-m", "services.cli", "foxglove", "--connect", self.endpoint,
             "--set", f"port={port}", "--set", "bus.zenoh.listen=[]", "--set",
             f"height_map={self.folder / 'crater.npz'}"], cwd=ROOT, stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE, text=True)
        try:
            wait_until(lambda: proc.poll() is not None or _handshake(port, None) == 101, 30,
                       0.3)
            statuses = {origin: _handshake(port, origin) for origin in
                        ("https://evil.example", "http://localhost:3000", None)}
            def inner_ports() -> list[int]:
                return [p for p in _listening_ports(proc.pid) if p != port]
            wait_until(inner_ports, 10, 0.2)  # the inner server listens soon after the gate
            ports = inner_ports()
            inner = {p: _handshake(p, "https://evil.example") for p in ports}
        finally:
            interrupt(proc, 10)
        ok = statuses == {"https://evil.example": 403, "http://localhost:3000": 101,
                          None: 101} and bool(inner) and 101 not in inner.values()
        self.rows.append(Row(
            "foreign Origin at stb foxglove", "a foreign page refused (403); this machine's "
            "page and a client without Origin served; the inner server behind the gate "
            "refuses a page that finds its port",
            "; ".join(f"{o or 'no Origin'}: {s}" for o, s in statuses.items()) +
            "; the inner port(s) to evil.example: " + (", ".join(
                f"{p}: {'opened' if s == 101 else 'refused'}" for p, s in inner.items())
                or "none found"), ok,
            {"statuses": {str(o): s for o, s in statuses.items()},
             "inner": {str(p): s for p, s in inner.items()}}))

    def crater_rewrite(self) -> None:
        """The crater file written again and again (as the sim does at start) while the
        page draws it and the gantry, killed meanwhile, loads it at its start."""
        path = self.folder / "crater.npz"
        crater = HeightMap.load(path)
        page = PageClient(self.web_url)
        pids, start = self.pids(), time.monotonic()
        statuses: dict[int, int] = {}
        killed_at = None
        rewrites = 100 if self.short else 300
        for i in range(rewrites):
            crater.save(path)
            if i % 5 == 0:
                status = page.request("GET", "/map.png", auth=VIEWER)[0]
                statuses[status] = statuses.get(status, 0) + 1
            if i == 10 and (pid := self.meters.pid("gantry")):
                os.kill(pid, signal.SIGKILL)
                killed_at = time.monotonic()
        back = None
        if killed_at is not None:
            wait_until(lambda: self.meters.alive_again(ALIVE["gantry"], killed_at) is not None,
                       20, 0.1)
            back = self.meters.alive_again(ALIVE["gantry"], killed_at)
        others = [s for s in self.meters.deaths(start) if s != f"stb/alive/{ALIVE['gantry']}"]
        ok = statuses == {200: sum(statuses.values())} and back is not None and not others \
            and all(self.pids()[s] == pids[s] for s in pids if s != "gantry")
        self.rows.append(Row(
            "crater file rewritten while read", "every map drawn (200); the gantry, killed "
            "meanwhile, starts on it; no other restart",
            f"{rewrites} rewrites: map.png {statuses}; gantry alive again "
            f"{duration_text(back)} after SIGKILL; other restarts {len(others)}", ok,
            {"statuses": statuses, "gantry_back_s": back}))


def _listening_ports(pid: int) -> list[int]:
    """The TCP ports a process listens on (its sockets' inodes in /proc/net/tcp and tcp6); a
    descriptor closed while they are read is passed over (it once made the list empty)."""
    inodes = set()
    try:
        fds = os.listdir(f"/proc/{pid}/fd")
    except OSError:
        return []
    for fd in fds:
        try:
            link = os.readlink(f"/proc/{pid}/fd/{fd}")
        except OSError:
            continue  # closed meanwhile
        if link.startswith("socket:"):
            inodes.add(link[8:-1])
    lines = []
    for table in ("tcp", "tcp6"):
        try:
            lines += Path(f"/proc/{pid}/net/{table}").read_text().splitlines()[1:]
        except OSError:
            continue
    return sorted({int(f[1].rsplit(":", 1)[1], 16) for f in (line.split() for line in lines)
                   if len(f) > 9 and f[3] == "0A" and f[9] in inodes})


def _handshake(port: int, origin: str | None) -> int:
    async def go() -> int:
        try:
            async with websockets.connect(f"ws://127.0.0.1:{port}", origin=origin,  # type: ignore[arg-type]
                                          subprotocols=SUBPROTOCOLS, open_timeout=5):
                return 101
        except websockets.InvalidStatus as err:
            return err.response.status_code
        except (OSError, TimeoutError, websockets.InvalidHandshake):
            return 0  # no WebSocket there (the inner server speaks TLS)
    return asyncio.run(go())
