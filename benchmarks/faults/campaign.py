"""The campaign: the lab, the meters, every fault in turn, the table."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from benchmarks.faults.bus_faults import BusFaults
from benchmarks.faults.file_faults import FileFaults
from benchmarks.faults.lab import (
    ALIVE,
    open_when_up,
    ports_of,
    running_lab,
    wait_until,
)
from benchmarks.faults.meters import Meters
from benchmarks.faults.process_faults import ProcessFaults
from benchmarks.faults.rows import Row
from benchmarks.faults.trust_faults import TrustFaults
from benchmarks.faults.web_faults import WebFaults
from common.bus import Bus
from common.settings import BusSettings, ZenohSettings


class Campaign(BusFaults, ProcessFaults, WebFaults, TrustFaults, FileFaults):
    """Every fault (the mixins), the baseline and the totals."""

    # --- steps ---

    def baseline(self) -> dict:
        # "tracking" comes while the crane still closes in on the robot
        time.sleep(3 if self.short else 5)
        start = time.monotonic()
        time.sleep(3 if self.short else 10)
        crane = self.meters.crane_window(start)
        self.normal_mm = float(crane[:, 3].max())  # the crane "with the robot" after a fault
        return {"rms_mm": float(np.sqrt(np.mean(crane[:, 3] ** 2))), "max_mm": self.normal_mm}

    def totals(self, started: float) -> None:
        crane = self.meters.crane_window(started)
        g = self.gantry
        setpoints = self.meters.setpoints_since(started)
        outside = sum(not (g.x_min_mm <= sp.x_mm <= g.x_max_mm and
                           g.y_min_mm <= sp.y_mm <= g.y_max_mm) for _, sp, _ in setpoints)
        inside = bool(((crane[:, 1] >= g.x_min_mm) & (crane[:, 1] <= g.x_max_mm) &
                       (crane[:, 2] >= g.y_min_mm) & (crane[:, 2] <= g.y_max_mm)).all())
        self.rows.append(Row(
            "whole campaign", "0 setpoints outside the workspace; crane inside it",
            f"{len(setpoints)} setpoints, {outside} outside; crane x {crane[:, 1].min():.0f}…"
            f"{crane[:, 1].max():.0f}, y {crane[:, 2].min():.0f}…{crane[:, 2].max():.0f} mm",
            outside == 0 and inside, {"setpoints": len(setpoints), "outside": outside}))



STEPS = ["quiet", "fuzz", "churn", "bombs", "frames", "pose", "drift", "calibration-flood",
         "command-flood", "origin", "crater-file", "streams", "sign-ins", "viewer-sign-ins",
         "forwarded-for", "host", "bodies", "report-link", "calibration-move", "disk-fill",
         "crater-import", "stalls", "tracker", "modbus", "camera-reboot", "kill"]


def run(short: bool, per_key: int, churn: int, folder: Path,
        only: list[str] | None = None) -> list[Row]:
    with running_lab(folder) as (up, lab, endpoint):
        ports = ports_of(lab)
        settings = BusSettings(zenoh=ZenohSettings(mode="client", connect=[endpoint]))
        session = open_when_up(settings.zenoh)
        bus = Bus(session, settings)
        meters = Meters(session, bus, ports["crane"])
        try:
            campaign = Campaign(up, meters, bus, session, short, ports["crane"],
                                f"http://127.0.0.1:{ports['web']}", endpoint, folder, lab)
            campaign.log("lab starting; waiting until every service is alive")
            if not wait_until(lambda: all(campaign.meters.pid(s) for s in ALIVE), 90, 0.5):
                raise SystemExit(f"the lab did not come up: see {folder / 'logs'}")
            if not campaign.follow(90):
                raise SystemExit(f"the crane never tracked: see {folder / 'logs'}")
            wait_until(lambda: any(p.camera == "ptz1" for _, p in meters.poses), 10)
            started = time.monotonic()
            baseline = campaign.baseline()
            campaign.log(f"baseline: crane–robot rms {baseline['rms_mm']:.0f} mm, "
                         f"max {baseline['max_mm']:.0f} mm")
            steps: dict[str, Callable[[], None]] = {
                "quiet": campaign.quiet,
                "fuzz": _each(campaign.fuzz, (per_key, False), (per_key, True)),
                "churn": _each(campaign.churn, (churn, False), (churn, True)),
                "bombs": campaign.decode_bombs,
                "frames": lambda: campaign.spoofed_frames(baseline),
                "pose": campaign.spoofed_pose,
                "drift": lambda: campaign.drifting_frames(baseline),
                "calibration-flood": lambda: campaign.calibration_flood(baseline),
                "command-flood": lambda: campaign.command_flood(baseline),
                "origin": campaign.foreign_origin,
                "crater-file": campaign.crater_rewrite,
                "streams": campaign.event_streams,
                "sign-ins": campaign.sign_in_flood,
                "viewer-sign-ins": campaign.viewer_sign_ins,
                "forwarded-for": campaign.forwarded_for,
                "host": campaign.foreign_host,
                "bodies": campaign.huge_bodies,
                "report-link": campaign.report_link,
                "calibration-move": campaign.calibration_move,
                "disk-fill": campaign.disk_filled,
                "crater-import": campaign.crater_imports,
                "stalls": _each(campaign.stall, *[("gantry", seconds) for seconds in
                                                  ((0.3, 1.0) if short else (0.3, 1.0, 3.0))]),
                "tracker": lambda: campaign.stall("tracker", 2.0),
                "modbus": lambda: campaign.foreign_modbus(baseline),
                "camera-reboot": campaign.camera_reboot,
                "kill": campaign.kill_each}
            for name in only or list(steps):
                began = time.monotonic()
                campaign.follow()  # each fault starts from a crane that follows the robot
                steps[name]()
                campaign.log(f"{name}: {time.monotonic() - began:.1f} s")
            campaign.totals(started)
            return campaign.rows
        finally:
            meters.close()
            bus.close()
            session.close()


def _each(step: Callable[..., None], *calls: tuple) -> Callable[[], None]:
    """A step that runs ``step`` once with each argument tuple, in turn."""
    def steps() -> None:
        for args in calls:
            step(*args)
    return steps


def table(rows: list[Row]) -> str:
    lines = ["| fault | goal | measured | held |", "|---|---|---|---|"]
    lines += [f"| {r.fault} | {r.goal} | {r.measured} | {'yes' if r.held else '**no**'} |"
              for r in rows]
    return "\n".join(lines)
