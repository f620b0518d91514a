"""Faults of processes and devices: SIGKILL, SIGSTOP, a router restart, a foreign Modbus
writer, the cameras rebooting."""

from __future__ import annotations

import os
import signal
import time

from pymodbus.client import ModbusTcpClient

from benchmarks.faults.base import CampaignBase
from benchmarks.faults.lab import ALIVE, SERVICES, children, cmdline, wait_until
from benchmarks.faults.rows import (
    GOAL_AIM_BACK_S,
    GOAL_AIM_DEG,
    GOAL_ALIVE_S,
    GOAL_FOREIGN_STOP_S,
    GOAL_WATCHDOG_S,
    POLL_S,
    Row,
    duration_text,
    quick_restart,
)
from common.crane_registers import DEFAULT_MAP, ENABLED, FAULTED
from tests.calib.test_demo_calibration import MOUNTS


class ProcessFaults(CampaignBase):
    """The processes' and devices' faults, as a part of ``Campaign``."""

    def kill_each(self) -> None:
        for service in [s for s in SERVICES if s != "router"]:
            if self.meters.pid(service) is None:
                self.rows.append(Row(f"SIGKILL {service}", "alive ≤ 2 s", "no pid heard", False))
                continue
            kills = [self._kill(service)]
            if not quick_restart([k["alive_again_s"] for k in kills]):
                kills.append(self._kill(service))  # once more, on warm caches (docs/reliability.md)
            backs = [k["alive_again_s"] for k in kills]
            text = "alive again after " + ", then ".join(duration_text(b) for b in backs)
            held = quick_restart(backs)
            figures: dict = {"alive_again_s": backs}
            if service == "gantry":
                trips = [k["crane_disabled_s"] for k in kills]
                figures["crane_disabled_s"] = trips
                text += "; crane disabled after " + ", then ".join(
                    duration_text(t) if t is not None else "(not enabled before the kill)"
                    for t in trips)
                held = held and all(t is not None and t <= GOAL_WATCHDOG_S + 2 * POLL_S
                                    for t in trips)
            self.rows.append(Row(f"SIGKILL {service}", "alive ≤ 2 s" + (
                "; crane disabled ≤ 0.5 s" if "crane_disabled_s" in figures else ""),
                text, held, figures))
            self.log(f"SIGKILL {service}: {text}")
        self.router_restart()

    def _kill(self, service: str) -> dict[str, float | None]:
        """SIGKILL the service once; when it is alive again (and the crane disabled, for the
        gantry), and its new process is up: the times."""
        pid = self.meters.pid(service)
        if pid is None:  # no health from it: nothing to kill, the goal missed
            self.log(f"{service}: no process known to kill")
            return {"alive_again_s": None}
        at = time.monotonic()
        os.kill(pid, signal.SIGKILL)
        wait_until(lambda: self.meters.alive_again(ALIVE[service], at) is not None, 20)
        figures = {"alive_again_s": self.meters.alive_again(ALIVE[service], at)}
        if service == "gantry":  # from an enabled crane only (else: None, the goal missed)
            enabled = bool(self.meters.status_at(at - 2 * POLL_S) & ENABLED)
            figures["crane_disabled_s"] = (self.meters.first_status(at, ENABLED, present=False)
                                           if enabled else None)
        # the next kill once this one is up again (its health from the new process): each
        # restart measured alone, not while the one before still loads
        wait_until(lambda: self.meters.pid(service) not in (None, pid), 10)
        if service in ("gantry", "sim"):  # it comes back disarmed; the crane disabled
            self.follow(since_s=time.time())
        time.sleep(0.3 if self.short else 1)
        return figures

    def router_restart(self) -> None:
        routers = [p for p in children(self.up.pid) if "services.router" in cmdline(p)]
        if not routers:
            self.rows.append(Row("router restart", "resumed ≤ 2 s", "no router process", False))
            return
        at = time.monotonic()
        os.kill(routers[0], signal.SIGKILL)
        names = {f"{s.replace(':', '/')}" if ":" in s else f"{s}/main" for s in ALIVE}
        wait_until(lambda: names <= self.meters.health_heard_after(at + 0.1), 30)
        heard = {}
        with self.meters.lock:
            for name in names:
                entry = self.meters.health.get(name)
                heard[name] = entry[0] - at if entry and entry[0] > at + 0.1 else None
        worst = max((v for v in heard.values() if v is not None), default=None)
        held = None not in heard.values() and worst is not None and worst <= GOAL_ALIVE_S + 1.0
        self.rows.append(Row(
            "router SIGKILL", "every service heard again ≤ 2 s after the router is back",
            f"router restarted by stb up; every service's health heard again after "
            f"{duration_text(worst)} (router restart included)", held, {"resumed_s": heard}))
        self.follow()

    def stall(self, service: str, seconds: float) -> None:
        pid = self.meters.pid(service)
        if pid is None:
            return
        at = time.monotonic()
        os.kill(pid, signal.SIGSTOP)
        time.sleep(seconds)
        os.kill(pid, signal.SIGCONT)
        resumed = time.monotonic()
        time.sleep(2)
        if service == "gantry":
            self._gantry_stall(seconds, at, resumed)
        else:
            ages = [age for t, age in self.meters.robot_ages if t > resumed]
            stale = sum(age > self.max_age_s for age in ages)
            self.rows.append(Row(
                f"SIGSTOP {service} {seconds:g} s",
                f"0 robot samples older than bus.max_age_s ({self.max_age_s} s) sent",
                f"{len(ages)} robot samples in 2 s after SIGCONT, {stale} older than "
                f"{self.max_age_s} s (oldest {max(ages, default=0):.2f} s)", stale == 0,
                {"stale_samples": stale, "samples": len(ages)}))

    def _gantry_stall(self, seconds: float, at: float, resumed: float) -> None:
        trip = self.meters.first_status(at, FAULTED, present=True)
        setpoints = self.meters.setpoints_since(resumed)
        stale = [age for t, sp, age in setpoints if not sp.hold and age > self.max_age_s
                 and self.meters.status_at(t) & ENABLED]
        expect_trip = seconds > GOAL_WATCHDOG_S
        tripped_in_time = trip is not None and trip <= GOAL_WATCHDOG_S + 2 * POLL_S
        held = (tripped_in_time if expect_trip else trip is None or trip > seconds) \
            and not stale
        ages = [age for _, sp, age in setpoints if not sp.hold]
        text = (f"watchdog tripped {duration_text(trip)} after SIGSTOP" if trip is not None and
                trip < seconds + 1 else "no watchdog trip") + \
            f"; {len(stale)} setpoints with an estimate older than {self.max_age_s} s " \
            "executed after SIGCONT"
        self.rows.append(Row(
            f"SIGSTOP gantry {seconds:g} s",
            "crane halted ≤ 0.5 s after the last write; 0 stale setpoints executed", text, held,
            {"watchdog_s": trip, "stale_setpoints": len(stale), "stale_ages_s": stale,
             "oldest_estimate_s": max(ages, default=None)}))
        self.log(f"SIGSTOP gantry {seconds:g} s: {text}")
        self.follow()

    def foreign_modbus(self, baseline: dict) -> None:
        """Another client writes setpoints 2 m outside the workspace at 10 Hz for 2 s."""
        client = ModbusTcpClient("127.0.0.1", port=self.crane_port, timeout=0.5, retries=0)
        start = time.monotonic()
        g = self.gantry
        written = 0
        for i in range(20):
            x = g.x_max_mm + 2000 if i % 2 else g.x_min_mm - 2000
            values = DEFAULT_MAP.encode("setpoint_x", x) + DEFAULT_MAP.encode("setpoint_y", 0)
            reply = client.write_registers(DEFAULT_MAP.setpoint_x, values,
                                           device_id=DEFAULT_MAP.unit_id)
            written += not reply.isError()
            time.sleep(0.1)
        client.close()
        time.sleep(1)
        crane = self.meters.crane_window(start)
        inside = bool(len(crane)) and bool(
            (crane[:, 1] >= g.x_min_mm).all() and (crane[:, 1] <= g.x_max_mm).all())
        worst = float(crane[:, 3].max()) if len(crane) else float("nan")
        with self.meters.lock:
            stopped = next((t - start for t, why in self.meters.stops
                            if t > start and "another Modbus client" in why), None)
        held = inside and stopped is not None and stopped <= GOAL_FOREIGN_STOP_S
        self.rows.append(Row(
            "foreign Modbus writer", "crane inside the workspace; the gantry stops it ≤ 1 s",
            f"{written} setpoint writes 2 m beyond the workspace over 2 s: the gantry stopped "
            f"the crane after {duration_text(stopped)}; crane x {crane[:, 1].min():.0f}…"
            f"{crane[:, 1].max():.0f} mm, max gap to the robot {worst:.0f} mm (baseline "
            f"{baseline['max_mm']:.0f})", held, {"stopped_s": stopped, "max_gap_mm": worst}))

    def camera_reboot(self) -> None:
        """The sim killed and started again by ``stb up``: its cameras go away and come back
        at home, as after a reboot. No camera may be taken for someone else's hand (it sat
        ``manual`` for 30 s at 11–15° true error), each aims at the robot again (true aim
        ≤ 1°) within 10 s of answering."""
        pid, at, at_wall = self.meters.pid("sim"), time.monotonic(), time.time()
        if pid is None:
            self.rows.append(Row("camera reboot", "≤ 1° within 10 s", "no sim pid", False))
            return
        os.kill(pid, signal.SIGKILL)
        wait_until(lambda: self.meters.pid("sim") not in (None, pid), 30)
        started = time.monotonic()  # the new sim's process is up: what comes now is its own
        cameras = sorted(MOUNTS)

        def back_at(camera: str) -> float | None:
            """When the camera answered again (its first truth from the new sim)."""
            return next((t for t, _ in self._aim(camera, started)), None)

        wait_until(lambda: all(back_at(c) is not None for c in cameras), 30)
        backs = {c: back_at(c) for c in cameras}

        def aimed() -> dict[str, float | None]:
            return {c: None if (b := backs[c]) is None else self._settled(
                b, self._aim(c, b), GOAL_AIM_DEG, GOAL_AIM_BACK_S) for c in cameras}

        last = max((b for b in backs.values() if b is not None), default=at)
        wait_until(lambda: None not in aimed().values(),
                   max(0.0, last + GOAL_AIM_BACK_S + 1.5 - time.monotonic()), 0.5)
        aim = aimed()
        manual = sorted({s.camera for s in self.meters.ptz_states
                         if s.measured_s >= at_wall and s.status == "manual"})
        misses = (["manual: " + ", ".join(manual)] if manual else []) + \
            [f"{c} not back" for c, a in aim.items() if a is None]
        self.rows.append(Row(
            "camera reboot", "not taken for a hand (manual); true aim ≤ 1° within 10 s of the "
            "camera answering", f"the sim killed, both cameras back at home: declared manual: "
            f"{', '.join(manual) or 'none'}; aim ≤ 1° after " + ", ".join(
                f"{c} {duration_text(a)}" for c, a in aim.items()), not misses,
            {"aim_back_s": aim, "manual": manual}, misses))
        self.log(f"camera reboot: {self.rows[-1].measured}")
        self.follow(since_s=time.time())  # the crane came back disarmed with the sim
